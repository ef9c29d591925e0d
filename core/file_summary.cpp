// SPDX-License-Identifier: MIT
#include "aneu/core/file_summary.hpp"

#include <filesystem>
#include <sstream>

#include "aneu/core/bundle_io.hpp"
#include "aneu/core/error.hpp"
#include "h5_detail.hpp"

namespace aneu {

namespace {

std::string dtype_name(const H5::DataSet& ds) {
    const H5T_class_t c = ds.getTypeClass();
    if (c == H5T_STRING) return "string";
    const size_t sz = ds.getDataType().getSize();
    if (c == H5T_FLOAT) return "float" + std::to_string(8 * sz);
    if (c == H5T_INTEGER) {
        const bool sign = ds.getIntType().getSign() != H5T_SGN_NONE;
        return std::string(sign ? "int" : "uint") + std::to_string(8 * sz);
    }
    return "other";
}

std::string filters_of(const H5::DataSet& ds) {
    const H5::DSetCreatPropList pl = ds.getCreatePlist();
    if (pl.getLayout() != H5D_CHUNKED) return "contiguous";
    std::string s = "chunked";
    const int nf = pl.getNfilters();
    for (int i = 0; i < nf; ++i) {
        unsigned flags = 0;
        size_t nelem = 0;
        unsigned cd[8];
        char name[64];
        unsigned cfg = 0;
        nelem = 8;
        const H5Z_filter_t id = pl.getFilter(i, flags, nelem, cd, sizeof name, name, cfg);
        s += i == 0 ? " " : "+";
        s += id == H5Z_FILTER_DEFLATE ? "gzip" : id == H5Z_FILTER_SHUFFLE ? "shuffle" : name;
    }
    return s;
}

std::string attr_text(const H5::Attribute& a) {
    const H5T_class_t c = a.getTypeClass();
    if (a.getSpace().getSimpleExtentNpoints() != 1) return "(array)";
    if (c == H5T_STRING) {
        std::string s;
        a.read(a.getStrType(), s);
        return s;
    }
    if (c == H5T_INTEGER) {
        long long v = 0;
        a.read(H5::PredType::NATIVE_LLONG, &v);
        return std::to_string(v);
    }
    if (c == H5T_FLOAT) {
        double v = 0;
        a.read(H5::PredType::NATIVE_DOUBLE, &v);
        std::ostringstream o;
        o.precision(10);
        o << v;
        return o.str();
    }
    return "(other)";
}

void visit(const H5::Group& g, const std::string& path, std::vector<H5Entry>& out) {
    for (const auto& name : h5::child_names(g)) {
        const std::string p = (path == "/" ? "" : path) + "/" + name;
        if (p == "/meta") continue;  // summarised as Meta
        H5Entry e;
        e.path = p;
        const H5O_type_t t = g.childObjType(name);
        if (t == H5O_TYPE_GROUP) {
            e.is_group = true;
            const H5::Group sub = g.openGroup(name);
            for (const auto& an : h5::attr_names(sub)) e.attributes.emplace_back(an, attr_text(sub.openAttribute(an)));
            out.push_back(e);
            visit(sub, p, out);
        } else if (t == H5O_TYPE_DATASET) {
            const H5::DataSet ds = g.openDataSet(name);
            const H5::DataSpace sp = ds.getSpace();
            const int r = sp.getSimpleExtentNdims();
            std::vector<hsize_t> d(static_cast<size_t>(std::max(r, 0)));
            if (r > 0) sp.getSimpleExtentDims(d.data());
            e.shape.assign(d.begin(), d.end());
            e.dtype = dtype_name(ds);
            e.stored_bytes = ds.getStorageSize();
            e.filters = filters_of(ds);
            for (const auto& an : h5::attr_names(ds)) {
                const std::string v = attr_text(ds.openAttribute(an));
                if (an == "units") {
                    e.units = v;
                } else {
                    e.attributes.emplace_back(an, v);
                }
            }
            out.push_back(e);
        }
    }
}

}  // namespace

const H5Entry* FileSummary::find(const std::string& p) const {
    for (const auto& e : entries) {
        if (e.path == p) return &e;
    }
    return nullptr;
}

FileSummary summarize_bundle(const std::string& path) {
    FileSummary s;
    s.path = path;
    s.meta = read_meta(path);
    H5::H5File f = h5::open_bundle(path);
    std::error_code ec;
    s.file_bytes = std::filesystem::file_size(path, ec);
    try {
        visit(f.openGroup("/"), "/", s.entries);
    } catch (const H5::Exception& e) {
        throw InputError(path + ": cannot list content (HDF5: " + h5::last_error_detail() + ")");
    }
    return s;
}

}  // namespace aneu
