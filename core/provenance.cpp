// SPDX-License-Identifier: MIT
#include "aneu/core/provenance.hpp"

#include <openssl/evp.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <memory>

#include "aneu/core/error.hpp"
#include "aneu/core/version.hpp"

namespace aneu {

namespace fs = std::filesystem;

namespace {

class Sha256 {
public:
    Sha256() : m_ctx(EVP_MD_CTX_new(), &EVP_MD_CTX_free) {
        if (!m_ctx || EVP_DigestInit_ex(m_ctx.get(), EVP_sha256(), nullptr) != 1) {
            throw Error("sha256: OpenSSL EVP initialisation failed");
        }
    }
    void update(const void* p, size_t n) { EVP_DigestUpdate(m_ctx.get(), p, n); }
    std::string hex() {
        std::array<unsigned char, EVP_MAX_MD_SIZE> md{};
        unsigned int len = 0;
        EVP_DigestFinal_ex(m_ctx.get(), md.data(), &len);
        static const char* digits = "0123456789abcdef";
        std::string s;
        for (unsigned i = 0; i < len; ++i) {
            s += digits[md[i] >> 4];
            s += digits[md[i] & 15];
        }
        return s;
    }

private:
    std::unique_ptr<EVP_MD_CTX, void (*)(EVP_MD_CTX*)> m_ctx;
};

std::string sha256_file(const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    if (!in) throw IoError(p.string() + ": cannot open for reading (to hash it)");
    Sha256 h;
    std::vector<char> buf(1 << 20);
    while (in) {
        in.read(buf.data(), static_cast<std::streamsize>(buf.size()));
        h.update(buf.data(), static_cast<size_t>(in.gcount()));
    }
    if (in.bad()) throw IoError(p.string() + ": read error while hashing");
    return h.hex();
}

}  // namespace

std::string sha256_hex(const std::string& bytes) {
    Sha256 h;
    h.update(bytes.data(), bytes.size());
    return h.hex();
}

std::string sha256_path(const std::string& path) {
    std::error_code ec;
    if (fs::is_directory(path, ec)) {
        std::vector<std::string> lines;
        for (const auto& e : fs::recursive_directory_iterator(path)) {
            if (!e.is_regular_file()) continue;
            lines.push_back(fs::relative(e.path(), path).generic_string() + " " + sha256_file(e.path()) + "\n");
        }
        std::sort(lines.begin(), lines.end());
        std::string all;
        for (const auto& l : lines) all += l;
        return sha256_hex(all);
    }
    if (!fs::exists(path, ec)) throw InputError(path + ": no such file (to hash it)");
    return sha256_file(path);
}

std::string read_file(const std::string& path) {
    std::ifstream f(path, std::ios::binary);
    if (!f) throw IoError(path + ": cannot open for reading");
    std::string out((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
    if (f.bad()) throw IoError(path + ": read failed");
    return out;
}

std::string utc_now_iso8601() {
    const std::time_t t = std::chrono::system_clock::to_time_t(std::chrono::system_clock::now());
    std::tm tm{};
    gmtime_r(&t, &tm);
    char buf[32];
    std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
    return buf;
}

std::string shell_join(const std::vector<std::string>& argv) {
    std::string out;
    for (const auto& a : argv) {
        if (!out.empty()) out += ' ';
        const bool plain = !a.empty() && std::all_of(a.begin(), a.end(), [](char c) {
            return std::isalnum(static_cast<unsigned char>(c)) || std::string("-_./=,:+@%").find(c) != std::string::npos;
        });
        if (plain) {
            out += a;
        } else {
            out += '\'';
            for (char c : a) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
            out += '\'';
        }
    }
    return out;
}

StageRecord make_stage_record(const std::string& stage, const std::string& command_line,
                              std::vector<std::pair<std::string, std::string>> parameters,
                              const std::vector<std::string>& input_paths) {
    StageRecord r;
    r.stage = stage;
    r.tool_version = tool_version();
    r.git_revision = git_revision();
    r.created_utc = utc_now_iso8601();
    r.command_line = command_line;
    r.parameters = std::move(parameters);
    for (const auto& p : input_paths) r.inputs.push_back({p, sha256_path(p)});
    return r;
}

}  // namespace aneu
