// SPDX-License-Identifier: MIT
#include "condensed_tiles.hpp"

#include <algorithm>
#include <map>

#include "aneu/core/bundle_io.hpp"
#include "aneu/core/error.hpp"

namespace aneu::detail {

namespace {

hsize_t tile_index(hsize_t I, hsize_t J) { return I * (I + 1) / 2 + J; }

/// Tile layout of an n×n symmetric matrix with tiles of edge b.
struct Layout {
    hsize_t n = 0, b = 0, nb = 0;
    Layout(hsize_t n_, hsize_t b_) : n(n_), b(b_), nb((n_ + b_ - 1) / b_) {}
    hsize_t tiles() const { return nb * (nb + 1) / 2; }
};

template <class S>
void write_tiles(H5::Group& g, const TiledSymmetric<S>& W, Reporter& rep) {
    const auto b = static_cast<hsize_t>(W.tile_size()), nb = static_cast<hsize_t>(W.tiles_per_side());
    const hsize_t dims[3] = {static_cast<hsize_t>(W.tile_count()), b, b};
    H5::DataSpace fspace(3, dims);
    H5::DSetCreatPropList plist;
    const hsize_t chunk[3] = {1, b, b};
    plist.setChunk(3, chunk);  // no compression: dense noise-like floats barely compress, loads must be fast
    H5::DataSet ds = g.createDataSet("W_tiles", h5::pred<S>(), fspace, plist);
    h5::write_attr(ds, "units", std::string("mm/N"));
    for (hsize_t I = 0; I < nb; ++I) {
        // Tile row I = tiles (I,0..I): contiguous in memory and in the file.
        const hsize_t start[3] = {tile_index(I, 0), 0, 0}, count[3] = {I + 1, b, b};
        fspace.selectHyperslab(H5S_SELECT_SET, count, start);
        H5::DataSpace mspace(3, count);
        ds.write(W.data().data() + tile_index(I, 0) * b * b, h5::pred<S>(), mspace, fspace);
        rep.progress("write W", static_cast<std::int64_t>(I + 1), static_cast<std::int64_t>(nb));
    }
}

/// Reads whole tiles of /condensed/W_tiles with H5Dread_chunk: W is stored uncompressed in the native
/// type, one chunk per tile, so each tile is one contiguous read that bypasses HDF5's selection and
/// conversion machinery (a hyperslab-union read of the same tiles measured ~10x slower).
struct TileReader {
    H5::DataSet ds;
    Layout L;
    bool f32 = true;  ///< stored type: float32 (else float64)

    template <class S>
    void read_tile(hsize_t t, S* dst) const {
        const hsize_t offset[3] = {t, 0, 0};
        std::uint32_t filters = 0;
        if (H5Dread_chunk(ds.getId(), H5P_DEFAULT, offset, &filters, dst) < 0) {
            throw H5::DataSetIException("read_tile", "H5Dread_chunk failed for tile " + std::to_string(t));
        }
    }
    /// Reads column block J in stored type S: buf tile k (k ≤ J) = tile (J,k); (k > J) = tile (k,J).
    template <class S>
    void read_column_block(hsize_t J, std::vector<S>& buf) const {
        const hsize_t bb = L.b * L.b;
        buf.resize(L.nb * bb);
        for (hsize_t k = 0; k < L.nb; ++k) read_tile(k <= J ? tile_index(J, k) : tile_index(k, J), buf.data() + k * bb);
    }
    /// W(i, J·b + c) for all i from a column block buffer.
    template <class S, class Out>
    void extract_column(const std::vector<S>& buf, hsize_t J, hsize_t c, Out&& out) const {
        const hsize_t bb = L.b * L.b;
        for (hsize_t I = 0; I < L.nb; ++I) {
            const S* t = buf.data() + I * bb;
            const hsize_t rows = std::min(L.b, L.n - I * L.b);
            const auto base = static_cast<Eigen::Index>(I * L.b);
            if (I <= J) {
                for (hsize_t r = 0; r < rows; ++r) out(base + static_cast<Eigen::Index>(r)) = t[c * L.b + r];
            } else {
                for (hsize_t r = 0; r < rows; ++r) out(base + static_cast<Eigen::Index>(r)) = t[r * L.b + c];
            }
        }
    }
};

TileReader open_tiles(const H5::H5File& f, const h5::Ctx& ctx, Eigen::Index n) {
    const H5::Group g = f.openGroup("/condensed");
    if (!h5::exists(g, "W_tiles")) {
        throw InputError(ctx.where("/condensed/W_tiles") + ": missing dataset (expected [tiles,b,b] float)");
    }
    const auto b = h5::read_attr_int(g, "/condensed", "tile_size", ctx);
    if (b <= 0) throw InputError(ctx.where("/condensed") + ": tile_size = " + std::to_string(b) + ", expected > 0");
    TileReader tr{g.openDataSet("W_tiles"), Layout(static_cast<hsize_t>(n), static_cast<hsize_t>(b))};
    const H5::DataType t = tr.ds.getDataType();
    if (t == H5::PredType::NATIVE_FLOAT) {
        tr.f32 = true;
    } else if (t == H5::PredType::NATIVE_DOUBLE) {
        tr.f32 = false;
    } else {
        throw InputError(ctx.where("/condensed/W_tiles") + ": expected native float32 or float64 data");
    }
    const H5::DSetCreatPropList pl = tr.ds.getCreatePlist();
    hsize_t chunk[3] = {0, 0, 0};
    if (pl.getLayout() != H5D_CHUNKED || pl.getChunk(3, chunk) != 3 || chunk[0] != 1 ||
        chunk[1] != static_cast<hsize_t>(b) || chunk[2] != static_cast<hsize_t>(b) || pl.getNfilters() != 0) {
        throw InputError(ctx.where("/condensed/W_tiles") + ": expected one uncompressed chunk per tile of " +
                         std::to_string(b) + "x" + std::to_string(b));
    }
    H5::DataSpace sp = tr.ds.getSpace();
    std::vector<hsize_t> d(3, 0);
    if (sp.getSimpleExtentNdims() != 3) throw InputError(ctx.where("/condensed/W_tiles") + ": expected rank 3");
    sp.getSimpleExtentDims(d.data());
    if (d[0] != tr.L.tiles() || d[1] != tr.L.b || d[2] != tr.L.b) {
        throw InputError(ctx.where("/condensed/W_tiles") + ": shape " + h5::shape_string(d) + ", expected " +
                      h5::shape_string({tr.L.tiles(), tr.L.b, tr.L.b}) + " for n = " + std::to_string(n) +
                      ", tile_size = " + std::to_string(b));
    }
    return tr;
}

template <class T>
Eigen::Matrix<T, Eigen::Dynamic, Eigen::Dynamic> read_columns(const std::string& path,
                                                               const std::vector<int>& cols) {
    H5::H5File f = h5::open_bundle(path);
    const h5::Ctx ctx{path};
    if (!h5::exists(f.openGroup("/"), "condensed")) {
        throw InputError(path + ": no /condensed group (the file is not a condensed case bundle)");
    }
    const CondensedData hdr = read_condensed_group(f, ctx, false);
    const Eigen::Index n = hdr.size();
    const TileReader tr = open_tiles(f, ctx, n);
    std::map<hsize_t, std::vector<size_t>> by_block;  // column block -> positions in cols
    for (size_t q = 0; q < cols.size(); ++q) {
        if (cols[q] < 0 || cols[q] >= n) {
            throw InputError(path + ": column " + std::to_string(cols[q]) + " of W requested, W has " +
                             std::to_string(n) + " columns");
        }
        by_block[static_cast<hsize_t>(cols[q]) / tr.L.b].push_back(q);
    }
    Eigen::Matrix<T, Eigen::Dynamic, Eigen::Dynamic> out(n, static_cast<Eigen::Index>(cols.size()));
    auto gather = [&](auto stored_zero) {
        std::vector<decltype(stored_zero)> buf;
        for (const auto& [J, qs] : by_block) {
            tr.read_column_block(J, buf);
            for (size_t q : qs) {
                T* col = out.col(static_cast<Eigen::Index>(q)).data();
                tr.extract_column(buf, J, static_cast<hsize_t>(cols[q]) % tr.L.b,
                                  [col](Eigen::Index i) -> T& { return col[i]; });
            }
        }
    };
    try {
        if (tr.f32) {
            gather(0.0f);
        } else {
            gather(0.0);
        }
    } catch (const H5::Exception& e) {
        throw InputError(path + ": /condensed/W_tiles: read failed (HDF5: " + h5::last_error_detail() + ")");
    }
    return out;
}

template <class S>
void read_full(const TileReader& tr, TiledSymmetric<S>& W) {
    W = TiledSymmetric<S>(static_cast<Eigen::Index>(tr.L.n), static_cast<Eigen::Index>(tr.L.b));
    const hsize_t bb = tr.L.b * tr.L.b;
    for (hsize_t t = 0; t < tr.L.tiles(); ++t) tr.read_tile(t, W.data().data() + t * bb);
}

}  // namespace

void write_condensed_group(H5::H5File& f, const CondensedData& c, Reporter& rep) {
    const Eigen::Index n = c.size();
    if (n == 0) throw InputError("write_bundle: condensed: empty DOF set");
    if (c.dof_axis.size() != n) throw InputError("write_bundle: condensed: dof_axis size != dof_node size");
    const bool f32 = c.precision == Precision::FLOAT32;
    const Eigen::Index size = f32 ? c.W32.size() : c.W64.size();
    const Eigen::Index tile = f32 ? c.W32.tile_size() : c.W64.tile_size();
    if (size != n || tile <= 0) {
        throw InputError("write_bundle: condensed: W" + std::string(f32 ? "32" : "64") + " is " + std::to_string(size) +
                         "x" + std::to_string(size) + ", expected " + std::to_string(n) + "x" + std::to_string(n) +
                         " (the size of the DOF map)");
    }
    for (Eigen::Index i = 0; i < n; ++i) {
        if (c.dof_axis[i] < 0 || c.dof_axis[i] > 2 || c.dof_node[i] < 0) {
            throw InputError("write_bundle: condensed: DOF " + std::to_string(i) + " maps to node " +
                             std::to_string(c.dof_node[i]) + " axis " + std::to_string(c.dof_axis[i]));
        }
    }
    H5::Group g = f.createGroup("/condensed");
    h5::write_attr(g, "n", static_cast<std::int64_t>(n));
    h5::write_attr(g, "tile_size", static_cast<std::int64_t>(tile));
    h5::write_attr(g, "layout", std::string("lower-tiles: tile (I,J), I>=J, at index I(I+1)/2+J, row-major"));
    h5::write_attr(g, "precision", std::string(f32 ? "float32" : "float64"));
    h5::write_attr(g, "method", c.method);
    h5::write_array(g, "dof_node", c.dof_node.data(), {static_cast<hsize_t>(n)}, "", 4);
    h5::write_array(g, "dof_axis", c.dof_axis.data(), {static_cast<hsize_t>(n)}, "", 4);
    H5::Group dg = g.createGroup("diagnostics");
    for (const auto& [k, v] : c.diagnostics) h5::write_attr(dg, k, v);
    if (f32) {
        write_tiles(g, c.W32, rep);
    } else {
        write_tiles(g, c.W64, rep);
    }
}

CondensedData read_condensed_group(const H5::H5File& f, const h5::Ctx& ctx, bool with_W) {
    const H5::Group g = f.openGroup("/condensed");
    CondensedData c;
    const auto n = h5::read_attr_int(g, "/condensed", "n", ctx);
    const std::string prec = h5::read_attr_string(g, "/condensed", "precision", ctx);
    if (prec != "float32" && prec != "float64") {
        throw InputError(ctx.where("/condensed") + ": precision = \"" + prec + "\", expected float32 or float64");
    }
    c.precision = prec == "float32" ? Precision::FLOAT32 : Precision::FLOAT64;
    c.method = h5::read_attr_string(g, "/condensed", "method", ctx);
    std::vector<hsize_t> d;
    const std::string doc = "[n] with n = " + std::to_string(n);
    auto node = h5::read_array<std::int32_t>(g, "/condensed", "dof_node", {n}, d, ctx, doc);
    auto axis = h5::read_array<std::int32_t>(g, "/condensed", "dof_axis", {n}, d, ctx, doc);
    c.dof_node = Eigen::Map<Eigen::VectorXi>(node.data(), static_cast<Eigen::Index>(n));
    c.dof_axis = Eigen::Map<Eigen::VectorXi>(axis.data(), static_cast<Eigen::Index>(n));
    if (!h5::exists(g, "diagnostics")) throw InputError(ctx.where("/condensed/diagnostics") + ": missing group");
    const H5::Group dg = g.openGroup("diagnostics");
    for (const auto& k : h5::attr_names(dg)) {
        c.diagnostics.emplace_back(k, h5::read_attr_double(dg, "/condensed/diagnostics", k, ctx));
    }
    const TileReader tr = open_tiles(f, ctx, static_cast<Eigen::Index>(n));  // validates the shape
    if (tr.f32 != (c.precision == Precision::FLOAT32)) {
        throw InputError(ctx.where("/condensed") + ": precision = \"" + prec + "\" but W_tiles holds " +
                         (tr.f32 ? "float32" : "float64"));
    }
    if (with_W) {
        if (tr.f32) {
            read_full(tr, c.W32);
        } else {
            read_full(tr, c.W64);
        }
    }
    return c;
}

}  // namespace aneu::detail

namespace aneu {

CondensedData read_condensed_header(const std::string& path) {
    H5::H5File f = h5::open_bundle(path);
    if (!h5::exists(f.openGroup("/"), "condensed")) {
        throw InputError(path + ": no /condensed group (the file is not a condensed case bundle)");
    }
    return detail::read_condensed_group(f, h5::Ctx{path}, false);
}

Eigen::MatrixXd read_condensed_columns(const std::string& path, const std::vector<int>& cols) {
    return detail::read_columns<double>(path, cols);
}

Eigen::MatrixXf read_condensed_columns_f(const std::string& path, const std::vector<int>& cols) {
    return detail::read_columns<float>(path, cols);
}

}  // namespace aneu
