// SPDX-License-Identifier: MIT
#include "aneu/fem/patch.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>

#include <Eigen/CholmodSupport>

#include "aneu/core/common.hpp"
#include "aneu/core/error.hpp"

namespace aneu::fem {

using RowSparse = Eigen::SparseMatrix<double, Eigen::RowMajor>;

struct PatchModel::Impl {
    std::vector<int> nodes;           // patch node -> global
    std::vector<int> local;           // global -> patch node or -1
    std::vector<char> interface;      // per patch node
    std::vector<int> iface_dof;       // interface DOF k -> patch DOF
    Eigen::VectorXi fixed;            // patch DOFs
    std::unique_ptr<NeoHookeanSolid> solid;
    Eigen::MatrixXd S;                // on the interface DOFs
    RowSparse pattern;
    std::vector<std::int64_t> solid_to_pattern;  // per solid pattern entry
    std::vector<std::int64_t> s_to_pattern;      // per S entry (row-major, iface_dof × iface_dof)
    // Exterior: its free DOFs, the factor of K_EE, and K_EI.
    Eigen::Index n_full = 0;
    std::vector<int> e_dof;           // E index -> global DOF
    Eigen::SparseMatrix<double> K_EI;  // |E| × #interface DOFs
    Eigen::CholmodSupernodalLLT<Eigen::SparseMatrix<double>, Eigen::Upper> llt;
    // Map nodes: per map DOF, the patch DOF it is (≥ 0), or −1 − its row in `map` (exterior), or INT_MIN (fixed).
    std::vector<int> map_src;
    Eigen::MatrixXd map;              // exterior map DOFs × interface DOFs: −K_EE⁻¹ K_EI rows
    double setup_s = 0, factor_s = 0, solves_s = 0;

    Eigen::VectorXd iface(const Eigen::VectorXd& u) const {
        Eigen::VectorXd x(static_cast<Eigen::Index>(iface_dof.size()));
        for (size_t k = 0; k < iface_dof.size(); ++k) x[static_cast<Eigen::Index>(k)] = u[iface_dof[k]];
        return x;
    }
};

namespace {

/// Every entry of the symmetric K (stored both triangles or upper only), once each.
template <class F>
void for_each_entry(const FemData& fem, F f) {
    const RowSparse& K = fem.K;
    for (Eigen::Index r = 0; r < K.outerSize(); ++r)
        for (RowSparse::InnerIterator it(K, r); it; ++it) {
            const Eigen::Index c = it.col();
            if (fem.K_upper_only) {
                if (c < r) continue;
                f(r, c, it.value());
                if (c != r) f(c, r, it.value());
            } else {
                f(r, c, it.value());
            }
        }
}

}  // namespace

PatchModel::PatchModel(const VolumeData& vol, const FemData& fem, const std::vector<int>& patch_tets, const std::vector<int>& map_nodes,
                       const std::atomic<bool>* cancel)
    : m(std::make_unique<Impl>()) {
    const Stopwatch clock;
    const Eigen::Index nn = vol.nodes.rows(), nt = vol.tets.rows();
    if (patch_tets.empty()) throw InputError("patch: no tetrahedra");
    if (fem.K.rows() != 3 * nn) throw InputError("patch: K has " + std::to_string(fem.K.rows()) + " rows, the mesh 3 × " + std::to_string(nn));
    std::vector<char> in_patch_tet(static_cast<size_t>(nt), 0);
    for (int t : patch_tets) {
        if (t < 0 || t >= nt) throw InputError("patch: tetrahedron " + std::to_string(t) + " outside the mesh");
        in_patch_tet[static_cast<size_t>(t)] = 1;
    }
    m->n_full = 3 * nn;
    m->local.assign(static_cast<size_t>(nn), -1);
    std::vector<char> touches_exterior(static_cast<size_t>(nn), 0);
    for (Eigen::Index t = 0; t < nt; ++t)
        for (Eigen::Index k = 0; k < vol.tets.cols(); ++k) {
            const int v = vol.tets(t, k);
            if (in_patch_tet[static_cast<size_t>(t)]) {
                if (m->local[static_cast<size_t>(v)] < 0) {
                    m->local[static_cast<size_t>(v)] = static_cast<int>(m->nodes.size());
                    m->nodes.push_back(v);
                }
            } else {
                touches_exterior[static_cast<size_t>(v)] = 1;
            }
        }
    const auto np = static_cast<Eigen::Index>(m->nodes.size());
    m->interface.assign(static_cast<size_t>(np), 0);
    for (Eigen::Index a = 0; a < np; ++a) {
        if (touches_exterior[static_cast<size_t>(m->nodes[static_cast<size_t>(a)])]) {
            m->interface[static_cast<size_t>(a)] = 1;
            for (int ax = 0; ax < 3; ++ax) m->iface_dof.push_back(static_cast<int>(3 * a + ax));
        }
    }
    if (m->iface_dof.empty()) throw InputError("patch: it holds the whole mesh (no linear exterior)");
    std::vector<char> fixed(static_cast<size_t>(3 * nn), 0);
    std::vector<int> pf;
    for (Eigen::Index k = 0; k < fem.fixed_dofs.size(); ++k) {
        const int d = fem.fixed_dofs[k];
        fixed[static_cast<size_t>(d)] = 1;
        const int a = m->local[static_cast<size_t>(d / 3)];
        if (a >= 0) pf.push_back(3 * a + d % 3);
    }
    m->fixed = Eigen::Map<Eigen::VectorXi>(pf.data(), static_cast<Eigen::Index>(pf.size()));

    // The patch solid, in patch numbering.
    Eigen::MatrixX3d Vp(np, 3);
    for (Eigen::Index a = 0; a < np; ++a) Vp.row(a) = vol.nodes.row(m->nodes[static_cast<size_t>(a)]);
    Eigen::MatrixXi Tp(static_cast<Eigen::Index>(patch_tets.size()), vol.tets.cols());
    Eigen::VectorXi Rp(Tp.rows());
    for (Eigen::Index r = 0; r < Tp.rows(); ++r) {
        const int t = patch_tets[static_cast<size_t>(r)];
        for (Eigen::Index k = 0; k < Tp.cols(); ++k) Tp(r, k) = m->local[static_cast<size_t>(vol.tets(t, k))];
        Rp[r] = vol.tet_region[t];
    }
    m->solid = std::make_unique<NeoHookeanSolid>(Vp, Tp, Rp, fem.materials);

    // Exterior DOFs (nodes outside the patch, not fixed) and the interface DOFs in global numbering.
    std::vector<int> e_index(static_cast<size_t>(3 * nn), -1), i_index(static_cast<size_t>(3 * nn), -1);
    for (Eigen::Index v = 0; v < nn; ++v) {
        if (m->local[static_cast<size_t>(v)] >= 0) continue;
        for (int ax = 0; ax < 3; ++ax) {
            const auto d = static_cast<size_t>(3 * v + ax);
            if (fixed[d]) continue;
            e_index[d] = static_cast<int>(m->e_dof.size());
            m->e_dof.push_back(static_cast<int>(d));
        }
    }
    const auto ni = static_cast<Eigen::Index>(m->iface_dof.size());
    for (Eigen::Index k = 0; k < ni; ++k) {
        const int pd = m->iface_dof[static_cast<size_t>(k)];
        i_index[static_cast<size_t>(3 * m->nodes[static_cast<size_t>(pd / 3)] + pd % 3)] = static_cast<int>(k);
    }
    const auto ne = static_cast<Eigen::Index>(m->e_dof.size());
    // The map nodes' DOFs: patch DOF, exterior row of the map, or fixed.
    std::vector<int> map_e;  // exterior index of each map row
    m->map_src.reserve(3 * map_nodes.size());
    for (int v : map_nodes) {
        if (v < 0 || v >= nn) throw InputError("patch: map node " + std::to_string(v) + " outside the mesh");
        for (int ax = 0; ax < 3; ++ax) {
            const int a = m->local[static_cast<size_t>(v)];
            const int e = e_index[static_cast<size_t>(3 * v + ax)];
            if (a >= 0) {
                m->map_src.push_back(3 * a + ax);
            } else if (e >= 0) {
                m->map_src.push_back(-1 - static_cast<int>(map_e.size()));
                map_e.push_back(e);
            } else {
                m->map_src.push_back(std::numeric_limits<int>::min());
            }
        }
    }
    m->map = Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(map_e.size()), ni);
    std::vector<Eigen::Triplet<double>> tee, tei;
    m->S = Eigen::MatrixXd::Zero(ni, ni);
    for_each_entry(fem, [&](Eigen::Index r, Eigen::Index c, double v) {
        const int er = e_index[static_cast<size_t>(r)], ec = e_index[static_cast<size_t>(c)];
        const int ir = i_index[static_cast<size_t>(r)], ic = i_index[static_cast<size_t>(c)];
        if (er >= 0 && ec >= 0 && er <= ec) tee.emplace_back(er, ec, v);
        if (er >= 0 && ic >= 0) tei.emplace_back(er, ic, v);
        if (ir >= 0 && ic >= 0) m->S(ir, ic) += v;
    });
    // − K^patch_II: the patch's linear stiffness (its tangent at rest) on the interface.
    const RowSparse K0 = m->solid->tangent(Eigen::VectorXd::Zero(3 * np));
    std::vector<int> iface_of_patch_dof(static_cast<size_t>(3 * np), -1);
    for (Eigen::Index k = 0; k < ni; ++k) iface_of_patch_dof[static_cast<size_t>(m->iface_dof[static_cast<size_t>(k)])] = static_cast<int>(k);
    for (Eigen::Index r = 0; r < K0.outerSize(); ++r) {
        const int a = iface_of_patch_dof[static_cast<size_t>(r)];
        if (a < 0) continue;
        for (RowSparse::InnerIterator it(K0, r); it; ++it) {
            const int b = iface_of_patch_dof[static_cast<size_t>(it.col())];
            if (b >= 0) m->S(a, b) -= it.value();
        }
    }
    if (ne > 0) {
        Eigen::SparseMatrix<double> Kee(ne, ne);
        Kee.setFromTriplets(tee.begin(), tee.end());
        m->K_EI.resize(ne, ni);
        m->K_EI.setFromTriplets(tei.begin(), tei.end());
        m->K_EI.makeCompressed();
        m->llt.cholmod().print = 0;
        const Stopwatch tf;
        m->llt.compute(Kee);
        m->factor_s = tf.seconds();
        if (m->llt.info() != Eigen::Success) throw NumericalError("patch: the exterior stiffness K_EE is not positive definite (is the model held?)");
        // − K_IE K_EE⁻¹ K_EI, in blocks of interface DOFs.
        const Stopwatch ts;
        constexpr Eigen::Index BLOCK = 64;
        for (Eigen::Index c0 = 0; c0 < ni; c0 += BLOCK) {
            if (cancel && cancel->load(std::memory_order_relaxed)) throw Cancelled("patch: setup cancelled");
            const Eigen::Index nc = std::min(BLOCK, ni - c0);
            const Eigen::MatrixXd B = Eigen::MatrixXd(m->K_EI.middleCols(c0, nc));
            const Eigen::MatrixXd X = m->llt.solve(B);
            m->S.middleCols(c0, nc).noalias() -= m->K_EI.transpose() * X;
            for (size_t r = 0; r < map_e.size(); ++r) m->map.row(static_cast<Eigen::Index>(r)).segment(c0, nc) = -X.row(map_e[r]);
        }
        m->solves_s = ts.seconds();
    }
    m->S = 0.5 * (m->S + m->S.transpose()).eval();

    // The tangent's pattern: the solid's and the dense interface block.
    const RowSparse& sp = m->solid->pattern();
    std::vector<Eigen::Triplet<double>> tp;
    tp.reserve(static_cast<size_t>(sp.nonZeros() + ni * ni));
    for (Eigen::Index r = 0; r < sp.outerSize(); ++r)
        for (RowSparse::InnerIterator it(sp, r); it; ++it) tp.emplace_back(static_cast<int>(r), static_cast<int>(it.col()), 0.0);
    for (Eigen::Index a = 0; a < ni; ++a)
        for (Eigen::Index b = 0; b < ni; ++b) tp.emplace_back(m->iface_dof[static_cast<size_t>(a)], m->iface_dof[static_cast<size_t>(b)], 0.0);
    m->pattern.resize(3 * np, 3 * np);
    m->pattern.setFromTriplets(tp.begin(), tp.end());
    m->pattern.makeCompressed();
    auto position = [&](Eigen::Index r, Eigen::Index c) {
        const int* cols = m->pattern.innerIndexPtr() + m->pattern.outerIndexPtr()[r];
        const int* end = m->pattern.innerIndexPtr() + m->pattern.outerIndexPtr()[r + 1];
        return static_cast<std::int64_t>(m->pattern.outerIndexPtr()[r] + (std::lower_bound(cols, end, static_cast<int>(c)) - cols));
    };
    m->solid_to_pattern.reserve(static_cast<size_t>(sp.nonZeros()));
    for (Eigen::Index r = 0; r < sp.outerSize(); ++r)
        for (RowSparse::InnerIterator it(sp, r); it; ++it) m->solid_to_pattern.push_back(position(r, it.col()));
    m->s_to_pattern.reserve(static_cast<size_t>(ni * ni));
    for (Eigen::Index a = 0; a < ni; ++a)
        for (Eigen::Index b = 0; b < ni; ++b) m->s_to_pattern.push_back(position(m->iface_dof[static_cast<size_t>(a)], m->iface_dof[static_cast<size_t>(b)]));
    m->setup_s = clock.seconds();
    if (std::getenv("ANEU_PATCH_TRACE"))
        std::fprintf(stderr, "patch: %zu nodes, %zu interface DOFs, %lld exterior DOFs: setup %.2f s (K_EE factor %.2f s, interface solves %.2f s)\n",
                     m->nodes.size(), m->iface_dof.size(), static_cast<long long>(ne), m->setup_s, m->factor_s, m->solves_s);
}

PatchModel::~PatchModel() = default;

Eigen::Index PatchModel::dofs() const { return m->solid->dofs(); }

double PatchModel::energy(const Eigen::VectorXd& u) const {
    const double e = m->solid->energy(u);
    if (!std::isfinite(e)) return e;
    const Eigen::VectorXd x = m->iface(u);
    return e + 0.5 * x.dot(m->S * x);
}

Eigen::VectorXd PatchModel::internal_force(const Eigen::VectorXd& u) const {
    Eigen::VectorXd g = m->solid->internal_force(u);
    const Eigen::VectorXd f = m->S * m->iface(u);
    for (size_t k = 0; k < m->iface_dof.size(); ++k) g[m->iface_dof[k]] += f[static_cast<Eigen::Index>(k)];
    return g;
}

Eigen::SparseMatrix<double, Eigen::RowMajor> PatchModel::tangent(const Eigen::VectorXd& u, bool project) const {
    RowSparse K = m->pattern;
    add_tangent(u, project, K.valuePtr(), nullptr);
    return K;
}

// The solid's tangent and the exterior's S at their places in the pattern, or at where[place] in a caller's matrix.
void PatchModel::add_tangent(const Eigen::VectorXd& u, bool project, double* values, const std::int64_t* where) const {
    const RowSparse Ks = m->solid->tangent(u, project);
    auto at = [&](std::int64_t place) -> double& { return values[where ? where[place] : place]; };
    for (size_t p = 0; p < m->solid_to_pattern.size(); ++p) at(m->solid_to_pattern[p]) += Ks.valuePtr()[p];
    const Eigen::Index ni = m->S.rows();
    size_t q = 0;
    for (Eigen::Index a = 0; a < ni; ++a)
        for (Eigen::Index b = 0; b < ni; ++b) at(m->s_to_pattern[q++]) += m->S(a, b);
}

const Eigen::SparseMatrix<double, Eigen::RowMajor>& PatchModel::pattern() const { return m->pattern; }
double PatchModel::min_jacobian(const Eigen::VectorXd& u) const { return m->solid->min_jacobian(u); }
const std::vector<int>& PatchModel::nodes() const { return m->nodes; }
int PatchModel::local(int global_node) const {
    return global_node >= 0 && static_cast<size_t>(global_node) < m->local.size() ? m->local[static_cast<size_t>(global_node)] : -1;
}
bool PatchModel::on_interface(int local_node) const { return m->interface[static_cast<size_t>(local_node)] != 0; }
Eigen::Index PatchModel::interface_nodes() const { return static_cast<Eigen::Index>(m->iface_dof.size() / 3); }
const Eigen::VectorXi& PatchModel::fixed_dofs() const { return m->fixed; }
double PatchModel::setup_seconds() const { return m->setup_s; }

Eigen::VectorXd PatchModel::restrict_to_patch(const Eigen::VectorXd& u_full) const {
    Eigen::VectorXd u(dofs());
    for (size_t a = 0; a < m->nodes.size(); ++a) u.segment<3>(static_cast<Eigen::Index>(3 * a)) = u_full.segment<3>(3 * m->nodes[a]);
    return u;
}

Eigen::VectorXd PatchModel::mapped_displacement(const Eigen::VectorXd& u_patch) const {
    Eigen::VectorXd out(static_cast<Eigen::Index>(m->map_src.size()));
    const Eigen::VectorXd ext = m->map.rows() > 0 ? Eigen::VectorXd(m->map * m->iface(u_patch)) : Eigen::VectorXd();
    for (size_t k = 0; k < m->map_src.size(); ++k) {
        const int s = m->map_src[k];
        out[static_cast<Eigen::Index>(k)] = s >= 0 ? u_patch[s] : s == std::numeric_limits<int>::min() ? 0.0 : ext[-1 - s];
    }
    return out;
}

Eigen::VectorXd PatchModel::full_displacement(const Eigen::VectorXd& u_patch) const {
    Eigen::VectorXd u = Eigen::VectorXd::Zero(m->n_full);
    for (size_t a = 0; a < m->nodes.size(); ++a) u.segment<3>(3 * m->nodes[a]) = u_patch.segment<3>(static_cast<Eigen::Index>(3 * a));
    if (!m->e_dof.empty()) {
        const Eigen::VectorXd rhs = -(m->K_EI * m->iface(u_patch));
        const Eigen::VectorXd x = m->llt.solve(rhs);
        for (size_t k = 0; k < m->e_dof.size(); ++k) u[m->e_dof[k]] = x[static_cast<Eigen::Index>(k)];
    }
    return u;
}

}  // namespace aneu::fem
