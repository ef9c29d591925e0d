// SPDX-License-Identifier: MIT
#include "h5_detail.hpp"

#include <algorithm>
#include <filesystem>
#include <sstream>

#include "aneu/core/bundle.hpp"
#include "aneu/core/error.hpp"

namespace aneu::h5 {

namespace {
herr_t walk_cb(unsigned, const H5E_error2_t* e, void* data) {
    auto* out = static_cast<std::string*>(data);
    if (e && e->desc && out->empty()) *out = e->desc;  // walked downward: the first is the innermost
    return 0;
}

H5::StrType vlen_string() { return H5::StrType(H5::PredType::C_S1, H5T_VARIABLE); }

template <class T> H5T_class_t class_of();
template <> H5T_class_t class_of<double>() { return H5T_FLOAT; }
template <> H5T_class_t class_of<float>() { return H5T_FLOAT; }
template <> H5T_class_t class_of<std::int32_t>() { return H5T_INTEGER; }
template <> H5T_class_t class_of<std::int64_t>() { return H5T_INTEGER; }
template <> H5T_class_t class_of<std::uint8_t>() { return H5T_INTEGER; }

const char* class_name(H5T_class_t c) {
    switch (c) {
        case H5T_INTEGER: return "integer";
        case H5T_FLOAT: return "float";
        case H5T_STRING: return "string";
        default: return "other";
    }
}
}  // namespace

std::string last_error_detail() {
    std::string s;
    H5Ewalk2(H5E_DEFAULT, H5E_WALK_DOWNWARD, walk_cb, &s);
    return s;
}

void silence_hdf5() {
    static const bool done = [] {
        H5::Exception::dontPrint();
        return true;
    }();
    (void)done;
}

std::string shape_string(const std::vector<hsize_t>& dims) {
    std::ostringstream o;
    o << '[';
    for (size_t i = 0; i < dims.size(); ++i) o << (i ? "," : "") << dims[i];
    o << ']';
    return o.str();
}

bool exists(const H5::Group& g, const std::string& name) {
    return H5Lexists(g.getId(), name.c_str(), H5P_DEFAULT) > 0;
}

H5::H5File open_bundle(const std::string& path) {
    silence_hdf5();
    namespace fs = std::filesystem;
    std::error_code ec;
    if (!fs::exists(path, ec)) throw InputError(path + ": no such file");
    if (fs::is_directory(path, ec)) throw InputError(path + ": is a directory, expected an HDF5 file (.h5)");
    const htri_t is_h5 = H5Fis_hdf5(path.c_str());
    if (is_h5 <= 0) {
        throw InputError(path + ": not an HDF5 file (no HDF5 signature; " +
                      std::to_string(fs::file_size(path, ec)) + " bytes)");
    }
    H5::H5File f;
    try {
        f.openFile(path, H5F_ACC_RDONLY);
    } catch (const H5::Exception&) {
        throw InputError(path + ": cannot open HDF5 file, truncated or corrupt (HDF5: " +
                      last_error_detail() + ")");
    }
    const Ctx ctx{path};
    const H5::Group root = f.openGroup("/");
    if (!exists(root, "meta")) throw InputError(path + ": not an aneuclip bundle (no /meta group)");
    const H5::Group meta = f.openGroup("/meta");
    if (!meta.attrExists("format") || read_attr_string(meta, "/meta", "format", ctx) != BUNDLE_FORMAT) {
        throw InputError(path + ": not an aneuclip bundle (/meta has no format = \"" +
                      std::string(BUNDLE_FORMAT) + "\")");
    }
    const auto v = read_attr_int(meta, "/meta", "schema_version", ctx);
    if (v != BUNDLE_SCHEMA_VERSION) {
        throw InputError(path + ": schema version " + std::to_string(v) + ", but this aneuclip (" +
                      "schema " + std::to_string(BUNDLE_SCHEMA_VERSION) +
                      ") reads only version " + std::to_string(BUNDLE_SCHEMA_VERSION) +
                      "; rebuild the file with this version");
    }
    return f;
}

template <class T>
void write_array(H5::Group& g, const std::string& name, const T* data, const std::vector<hsize_t>& dims,
                 const std::string& units, int deflate_level) {
    hsize_t n = 1;
    for (auto d : dims) n *= d;
    H5::DataSpace space(static_cast<int>(dims.size()), dims.data());
    H5::DSetCreatPropList plist;
    if (n >= 4096 && deflate_level > 0) {
        // Chunks of ~256 KiB along the first dimension; the rest of each row stays in the chunk.
        std::vector<hsize_t> chunk = dims;
        hsize_t row = n / std::max<hsize_t>(dims[0], 1);
        chunk[0] = std::clamp<hsize_t>((256 * 1024 / sizeof(T)) / std::max<hsize_t>(row, 1), 1, dims[0]);
        plist.setChunk(static_cast<int>(chunk.size()), chunk.data());
        plist.setShuffle();
        plist.setDeflate(deflate_level);
    }
    H5::DataSet ds = g.createDataSet(name, pred<T>(), space, plist);
    if (n > 0) ds.write(data, pred<T>());
    if (!units.empty()) write_attr(ds, "units", units);
}

void write_strings(H5::Group& g, const std::string& name, const std::vector<std::string>& s) {
    const hsize_t n = s.size();
    H5::DataSpace space(1, &n);
    const H5::StrType st = vlen_string();
    H5::DataSet ds = g.createDataSet(name, st, space);
    std::vector<const char*> p;
    p.reserve(s.size());
    for (const auto& x : s) p.push_back(x.c_str());
    if (n > 0) ds.write(p.data(), st);
}

void write_attr(H5::H5Object& o, const std::string& name, const std::string& v) {
    const H5::StrType st = vlen_string();
    H5::Attribute a = o.createAttribute(name, st, H5::DataSpace(H5S_SCALAR));
    a.write(st, v);
}
void write_attr(H5::H5Object& o, const std::string& name, double v) {
    H5::Attribute a = o.createAttribute(name, H5::PredType::NATIVE_DOUBLE, H5::DataSpace(H5S_SCALAR));
    a.write(H5::PredType::NATIVE_DOUBLE, &v);
}
void write_attr(H5::H5Object& o, const std::string& name, std::int64_t v) {
    H5::Attribute a = o.createAttribute(name, H5::PredType::NATIVE_INT64, H5::DataSpace(H5S_SCALAR));
    a.write(H5::PredType::NATIVE_INT64, &v);
}

template <class T>
std::vector<T> read_array(const H5::Group& g, const std::string& path_in_file, const std::string& name,
                          const std::vector<long long>& dims_expected, std::vector<hsize_t>& dims,
                          const Ctx& ctx, const std::string& shape_doc) {
    const std::string obj = path_in_file + "/" + name;
    if (!exists(g, name)) {
        throw InputError(ctx.where(obj) + ": missing dataset (expected " + shape_doc + " " +
                      class_name(class_of<T>()) + ")");
    }
    H5::DataSet ds = g.openDataSet(name);
    const H5T_class_t cls = ds.getTypeClass();
    if (cls != class_of<T>()) {
        throw InputError(ctx.where(obj) + ": type " + class_name(cls) + ", expected " +
                      class_name(class_of<T>()));
    }
    H5::DataSpace space = ds.getSpace();
    const int rank = space.getSimpleExtentNdims();
    dims.assign(static_cast<size_t>(std::max(rank, 0)), 0);
    if (rank > 0) space.getSimpleExtentDims(dims.data());
    bool ok = rank == static_cast<int>(dims_expected.size());
    for (size_t i = 0; ok && i < dims.size(); ++i) {
        ok = dims_expected[i] < 0 || static_cast<long long>(dims[i]) == dims_expected[i];
    }
    if (!ok) {
        throw InputError(ctx.where(obj) + ": shape " + shape_string(dims) + ", expected " + shape_doc);
    }
    hsize_t n = 1;
    for (auto d : dims) n *= d;
    std::vector<T> out(n);
    if (n > 0) {
        try {
            ds.read(out.data(), pred<T>());
        } catch (const H5::Exception&) {
            throw InputError(ctx.where(obj) + ": cannot read data (HDF5: " + last_error_detail() + ")");
        }
    }
    return out;
}

std::vector<std::string> read_strings(const H5::Group& g, const std::string& path_in_file,
                                      const std::string& name, const Ctx& ctx) {
    const std::string obj = path_in_file + "/" + name;
    if (!exists(g, name)) throw InputError(ctx.where(obj) + ": missing dataset (expected [n] strings)");
    H5::DataSet ds = g.openDataSet(name);
    if (ds.getTypeClass() != H5T_STRING) throw InputError(ctx.where(obj) + ": expected a string dataset");
    H5::DataSpace space = ds.getSpace();
    if (space.getSimpleExtentNdims() != 1) throw InputError(ctx.where(obj) + ": expected a 1-d string list");
    hsize_t n = 0;
    space.getSimpleExtentDims(&n);
    std::vector<std::string> out;
    if (n == 0) return out;
    const H5::StrType st = vlen_string();
    std::vector<char*> buf(n, nullptr);
    ds.read(buf.data(), st);
    out.reserve(n);
    for (char* p : buf) out.emplace_back(p ? p : "");
    H5Dvlen_reclaim(st.getId(), space.getId(), H5P_DEFAULT, buf.data());
    return out;
}

std::string read_attr_string(const H5::H5Object& o, const std::string& obj_path, const std::string& name,
                             const Ctx& ctx) {
    if (!o.attrExists(name)) throw InputError(ctx.where(obj_path) + ": missing attribute '" + name + "'");
    H5::Attribute a = o.openAttribute(name);
    if (a.getTypeClass() != H5T_STRING) {
        throw InputError(ctx.where(obj_path) + ": attribute '" + name + "' is not a string");
    }
    std::string s;
    a.read(a.getStrType(), s);
    return s;
}

double read_attr_double(const H5::H5Object& o, const std::string& obj_path, const std::string& name,
                        const Ctx& ctx) {
    if (!o.attrExists(name)) throw InputError(ctx.where(obj_path) + ": missing attribute '" + name + "'");
    H5::Attribute a = o.openAttribute(name);
    const auto c = a.getTypeClass();
    if (c != H5T_FLOAT && c != H5T_INTEGER) {
        throw InputError(ctx.where(obj_path) + ": attribute '" + name + "' is not a number");
    }
    double v = 0;
    a.read(H5::PredType::NATIVE_DOUBLE, &v);
    return v;
}

std::int64_t read_attr_int(const H5::H5Object& o, const std::string& obj_path, const std::string& name,
                           const Ctx& ctx) {
    if (!o.attrExists(name)) throw InputError(ctx.where(obj_path) + ": missing attribute '" + name + "'");
    H5::Attribute a = o.openAttribute(name);
    if (a.getTypeClass() != H5T_INTEGER) {
        throw InputError(ctx.where(obj_path) + ": attribute '" + name + "' is not an integer");
    }
    std::int64_t v = 0;
    a.read(H5::PredType::NATIVE_INT64, &v);
    return v;
}

std::vector<std::string> attr_names(const H5::H5Object& o) {
    std::vector<std::string> out;
    const int n = o.getNumAttrs();
    for (int i = 0; i < n; ++i) out.push_back(o.openAttribute(static_cast<unsigned>(i)).getName());
    return out;
}

std::vector<std::string> child_names(const H5::Group& g) {
    std::vector<std::string> out;
    const hsize_t n = g.getNumObjs();
    for (hsize_t i = 0; i < n; ++i) out.push_back(g.getObjnameByIdx(i));
    std::sort(out.begin(), out.end());
    return out;
}

#define ANEU_H5_INSTANTIATE(T)                                                                       \
    template void write_array<T>(H5::Group&, const std::string&, const T*, const std::vector<hsize_t>&, \
                                 const std::string&, int);                                            \
    template std::vector<T> read_array<T>(const H5::Group&, const std::string&, const std::string&,  \
                                          const std::vector<long long>&, std::vector<hsize_t>&,      \
                                          const Ctx&, const std::string&);
ANEU_H5_INSTANTIATE(double)
ANEU_H5_INSTANTIATE(float)
ANEU_H5_INSTANTIATE(std::int32_t)
ANEU_H5_INSTANTIATE(std::int64_t)
ANEU_H5_INSTANTIATE(std::uint8_t)
#undef ANEU_H5_INSTANTIATE

}  // namespace aneu::h5
