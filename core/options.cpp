// SPDX-License-Identifier: MIT
#include "aneu/core/options.hpp"

#include <algorithm>
#include <cctype>

namespace aneu::opt {

namespace {
std::string num(double x) { return shortest(x); }
}  // namespace

Bound any() { return Bound{}; }
Bound gt(double x) { return Bound{x, std::numeric_limits<double>::infinity(), true, false, "> " + num(x)}; }
Bound ge(double x) { return Bound{x, std::numeric_limits<double>::infinity(), false, false, ">= " + num(x)}; }
Bound open(double a, double b) { return Bound{a, b, true, true, "in (" + num(a) + ", " + num(b) + ")"}; }
Bound closed(double a, double b) { return Bound{a, b, false, false, "in [" + num(a) + ", " + num(b) + "]"}; }
Bound closed_open(double a, double b) { return Bound{a, b, false, true, "in [" + num(a) + ", " + num(b) + ")"}; }
Bound open_closed(double a, double b) { return Bound{a, b, true, false, "in (" + num(a) + ", " + num(b) + "]"}; }

std::string Option::help_text() const {
    std::string h = help;
    if (!unit.empty()) h += " [" + unit + "]";
    if (!choices.empty()) {
        std::string c;
        for (const auto& w : choices) c += (c.empty() ? "" : ", ") + w;
        h += " {" + c + "}";
    }
    if (!rule.empty()) h += "; " + rule;
    return h;
}

double parse_number(const std::string& text, const std::string& what) {
    std::string t = text;
    t.erase(t.begin(), std::find_if(t.begin(), t.end(), [](unsigned char c) { return !std::isspace(c); }));
    t.erase(std::find_if(t.rbegin(), t.rend(), [](unsigned char c) { return !std::isspace(c); }).base(), t.end());
    try {
        std::size_t used = 0;
        const double v = std::stod(t, &used);
        if (used == t.size() && std::isfinite(v)) return v;
    } catch (const std::exception&) {
    }
    throw InputError(what + " '" + text + "': expected a number");
}

long long parse_integer(const std::string& text, const std::string& what) {
    try {
        std::size_t used = 0;
        const long long v = std::stoll(text, &used);
        if (used == text.size()) return v;
    } catch (const std::exception&) {
    }
    throw InputError(what + " '" + text + "': expected an integer");
}

bool parse_bool(const std::string& text, const std::string& what) {
    std::string t = text;
    std::transform(t.begin(), t.end(), t.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    if (t == "true" || t == "1" || t == "yes" || t == "on") return true;
    if (t == "false" || t == "0" || t == "no" || t == "off") return false;
    throw InputError(what + " '" + text + "': expected true or false");
}

std::vector<std::string> split_commas(const std::vector<std::string>& values) {
    std::vector<std::string> words;
    for (const auto& s : values) {
        std::size_t pos = 0;
        while (pos <= s.size()) {
            const std::size_t c = s.find(',', pos);
            words.push_back(s.substr(pos, c == std::string::npos ? std::string::npos : c - pos));
            if (c == std::string::npos) break;
            pos = c + 1;
        }
    }
    return words;
}

std::vector<double> parse_numbers(const std::vector<std::string>& values, std::size_t n, const std::string& what) {
    const std::vector<std::string> words = split_commas(values);
    if (words.size() != n) {
        throw InputError(what + ": expected " + std::to_string(n) + " comma-separated numbers, got " + std::to_string(words.size()));
    }
    std::vector<double> out;
    for (const auto& w : words) out.push_back(parse_number(w, what));
    return out;
}

}  // namespace aneu::opt
