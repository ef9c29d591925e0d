// SPDX-License-Identifier: MIT
// Contact on a precomputed compliance (compliance.hpp): the linearisation (tangent, factor, free step, the
// candidates' compliance) and the clip frame (a linear complementarity problem on the Delassus matrix, projected
// Gauss–Seidel).
#include "aneu/fem/compliance.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <iterator>
#include <limits>
#include <map>
#include <numeric>
#include <set>
#include <string>
#include <utility>

#include <Eigen/Cholesky>
#include <Eigen/Geometry>
#include <Eigen/CholmodSupport>
#include <Eigen/SparseCore>

#include "aneu/core/common.hpp"
#include "aneu/core/error.hpp"
#include "aneu/fem/condense.hpp"
#include "aneu/fem/contact.hpp"
#include "merged_pattern.hpp"

extern "C" {
void dpotrf_(const char* uplo, const int* n, double* a, const int* lda, int* info);
}

namespace aneu::fem {

struct Linearisation::Impl {
    Eigen::VectorXd u0, r0, free_u;
    Eigen::VectorXd free_body_u;  // the whole body's displacement at the free state, u0 + Δu_free
    Eigen::MatrixX3d free_x;
    std::vector<int> cand;
    std::vector<int> free_index;  // per body DOF: its index among the free ones, −1 fixed
    Eigen::Index nfree = 0;
    // W in 3 x 3 blocks: block (a, b) at 9 (b |C| + a), column-major; shared with the linearisations that borrow it
    std::shared_ptr<std::vector<double>> Wb = std::make_shared<std::vector<double>>();
    std::shared_ptr<const Eigen::VectorXd> w_u0;  // the state W was made at
    bool borrowed = false;
    std::shared_ptr<CondenseFactor> factor;  // the tangent's factor, condense's (with candidates)
    // The factor of the tangent W was made on (this one's, or the lender's): a borrowing linearisation on other
    // candidates makes the added ones' columns on it, so that W stays one tangent's inverse (positive definite)
    std::shared_ptr<const CondenseFactor> w_factor;
    Eigen::CholmodSupernodalLLT<Eigen::SparseMatrix<double>, Eigen::Upper> llt;  // without candidates
    Eigen::VectorXd solve(const Eigen::VectorXd& b) const { return factor ? factor->solve(b) : Eigen::VectorXd(llt.solve(b)); }
};



Linearisation::Linearisation(const ElasticBody& body, const Eigen::MatrixX3d& X, const Eigen::VectorXi& fixed_dofs, const Eigen::VectorXd& u0,
                             const std::vector<int>& candidates, bool project_first)
    : m(std::make_unique<Impl>()) {
    init(body, X, fixed_dofs, u0, candidates, nullptr, project_first);
}

Linearisation::Linearisation(const ElasticBody& body, const Eigen::MatrixX3d& X, const Eigen::VectorXi& fixed_dofs, const Eigen::VectorXd& u0,
                             const Linearisation& from, bool project_first)
    : m(std::make_unique<Impl>()) {
    if (from.m->u0.size() != body.dofs())
        throw InputError("linearisation: borrowing the compliance of a linearisation of " + std::to_string(from.m->u0.size()) + " DOFs for a body of " +
                         std::to_string(body.dofs()));
    init(body, X, fixed_dofs, u0, from.m->cand, &from, project_first);
}

Linearisation::Linearisation(const ElasticBody& body, const Eigen::MatrixX3d& X, const Eigen::VectorXi& fixed_dofs, const Eigen::VectorXd& u0,
                             const std::vector<int>& candidates, const Linearisation& from, bool project_first)
    : m(std::make_unique<Impl>()) {
    if (from.m->u0.size() != body.dofs())
        throw InputError("linearisation: borrowing the compliance of a linearisation of " + std::to_string(from.m->u0.size()) + " DOFs for a body of " +
                         std::to_string(body.dofs()));
    init(body, X, fixed_dofs, u0, candidates, &from, project_first);
}

void Linearisation::init(const ElasticBody& body, const Eigen::MatrixX3d& X, const Eigen::VectorXi& fixed_dofs, const Eigen::VectorXd& u0,
                         const std::vector<int>& candidates, const Linearisation* from, bool project_first) {
    const Eigen::Index n = body.dofs();
    if (u0.size() != n) throw InputError("linearisation: the state has " + std::to_string(u0.size()) + " entries, expected " + std::to_string(n));
    if (3 * X.rows() != n) throw InputError("linearisation: " + std::to_string(X.rows()) + " nodes for a body of " + std::to_string(n) + " DOFs");
    m->free_index.assign(static_cast<size_t>(n), 0);
    for (Eigen::Index k = 0; k < fixed_dofs.size(); ++k) {
        const int d = fixed_dofs[k];
        if (d < 0 || d >= n) throw InputError("linearisation: fixed DOF " + std::to_string(d) + " outside the body");
        m->free_index[static_cast<size_t>(d)] = -1;
    }
    for (Eigen::Index i = 0; i < n; ++i)
        if (m->free_index[static_cast<size_t>(i)] >= 0) m->free_index[static_cast<size_t>(i)] = static_cast<int>(m->nfree++);
    std::vector<char> seen(static_cast<size_t>(X.rows()), 0);
    for (int c : candidates) {
        if (c < 0 || c >= X.rows()) throw InputError("linearisation: candidate node " + std::to_string(c) + " outside the body");
        if (seen[static_cast<size_t>(c)]++) throw InputError("linearisation: candidate node " + std::to_string(c) + " given twice");
    }
    m->u0 = u0;
    m->cand = candidates;
    const Eigen::Index mf = m->nfree;

    Stopwatch sw;
    const Eigen::VectorXd g = body.internal_force(u0);
    m->r0 = Eigen::VectorXd::Zero(mf);
    for (Eigen::Index i = 0; i < n; ++i)
        if (const int a = m->free_index[static_cast<size_t>(i)]; a >= 0) m->r0[a] = -g[i];
    // project_first: the element tangents projected from the start (the caller expects this tangent to be indefinite,
    // the last one having been: its failed factorisation is not made)
    Eigen::SparseMatrix<double, Eigen::RowMajor> Kt = body.tangent(u0, project_first);
    projected = projected_first = project_first;
    tangent_s = sw.lap();
    // The tangent is factorised once: by the condensation that makes W (fem::condense: METIS on the node graph, the
    // forward solve L⁻¹ P E_C from the candidates' pivots, W = YᵀY by SYRK per supernode), its factor kept for the free
    // step and the frames' displacements. (Before: a factor of its own for those, then condense's; the sample's refresh
    // factorised the tangent twice, three times where it was projected.) Without candidates, a factor alone.
    std::vector<int> kept;
    for (int c : candidates)
        for (int ax = 0; ax < 3; ++ax)
            if (m->free_index[static_cast<size_t>(3 * c + ax)] >= 0) kept.push_back(3 * c + ax);
    CondensedData cd;
    double w_s = 0;
    auto factorise = [&]() {
        if (mf == 0) return true;
        if (!kept.empty() && !from) {
            CondenseParams cp;
            cp.precision = Precision::FLOAT64;
            cp.residual_columns = 0;  // checked by the tests instead
            std::unique_ptr<CondenseFactor> made;
            try {
                cd = condense(Kt, fixed_dofs, Eigen::Map<const Eigen::VectorXi>(kept.data(), static_cast<Eigen::Index>(kept.size())), cp,
                              null_reporter(), &made);
            } catch (const NumericalError&) {
                return false;
            }
            m->factor = std::move(made);
            for (const auto& [k, v] : cd.diagnostics) {
                if (k == "w_s") w_s = v;
                if (k == "n_free_dofs") free_dofs = v;
                if (k == "n_kept_dofs") kept_dofs = v;
                if (k == "nnz_L") nnz_L = v;
                if (k == "factor_flops") factor_flops = v;
                if (k == "w_flops") w_flops = v;
                if (k == "w_gflops_per_s") w_gflops_per_s = v;
            }
            return true;
        }
        m->llt.cholmod().print = 0;
        m->llt.compute(detail::free_upper(Kt, m->free_index, mf));
        return m->llt.info() == Eigen::Success;
    };
    double failed_s = 0;
    if (!factorise()) {  // buckling: the element tangents projected onto PSD ones
        if (project_first)
            throw NumericalError("linearisation: the tangent is not positive definite, even projected (" + std::to_string(mf) + " free DOFs)");
        failed_s = sw.lap();
        projected = true;
        Kt = body.tangent(u0, true);
        tangent_s += sw.lap();
        if (!factorise())
            throw NumericalError("linearisation: the tangent is not positive definite, even projected (" + std::to_string(mf) + " free DOFs)");
    }
    factorise_s = failed_s + sw.lap() - w_s;
    compliance_s = w_s;

    Eigen::VectorXd du = mf > 0 ? m->solve(m->r0) : Eigen::VectorXd();
    // The free step is a Newton step from u0, which frames far from their last linearisation leave far from
    // equilibrium: shortened (halved, at most 10 times) until it inverts no element, and the residual with it, so
    // that the frames on this linearisation are the damped step's (the tube's refresh on another thread, from a state
    // the frames had taken 3.7 wall thicknesses from theirs: the full step inverted an element, and every refresh
    // after it was refused).
    if (mf > 0) {
        Eigen::VectorXd ut = u0;
        auto trial = [&](double a) {
            ut = u0;
            for (Eigen::Index i = 0; i < n; ++i)
                if (const int k = m->free_index[static_cast<size_t>(i)]; k >= 0) ut[i] += a * du[k];
            return body.min_jacobian(ut) > 0;
        };
        double a = 1;
        for (int h = 0; h < 10 && !trial(a); ++h) a *= 0.5;
        if (a < 1) {
            free_step = a;
            du *= a;
            m->r0 *= a;
        }
    }
    m->free_body_u = u0;
    for (Eigen::Index i = 0; i < n; ++i)
        if (const int a = m->free_index[static_cast<size_t>(i)]; a >= 0) m->free_body_u[i] += du[a];
    m->free_x.resize(static_cast<Eigen::Index>(candidates.size()), 3);
    m->free_u.resize(3 * static_cast<Eigen::Index>(candidates.size()));
    for (size_t k = 0; k < candidates.size(); ++k) {
        const int c = candidates[k];
        for (int ax = 0; ax < 3; ++ax) {
            const Eigen::Index dof = 3 * c + ax;
            const int a = m->free_index[static_cast<size_t>(dof)];
            m->free_u[static_cast<Eigen::Index>(3 * k) + ax] = u0[dof] + (a >= 0 ? du[a] : 0.0);
            m->free_x(static_cast<Eigen::Index>(k), ax) = X(c, ax) + m->free_u[static_cast<Eigen::Index>(3 * k) + ax];
        }
    }
    // W = (K0⁻¹)_CC, made above, stored in 3 x 3 node blocks, a column of blocks contiguous: a frame reads the blocks
    // of the candidates its rows touch, 72 contiguous bytes each. (The sample's refresh, 1,448 candidates on 34,662
    // DOFs: compliance 12.7 -> 7.3 s, factorisation included, by condense instead of 3|C| substitutions; W equal to the
    // substitutions' (the test compares them column by column).)
    const Eigen::Index nc = 3 * static_cast<Eigen::Index>(candidates.size()), ncand = static_cast<Eigen::Index>(candidates.size());
    if (from) {  // borrowed: the other linearisation's W, shared where the candidates are its own
        free_dofs = static_cast<double>(mf);
        kept_dofs = static_cast<double>(kept.size());
        m->w_u0 = from->m->w_u0;
        m->w_factor = from->m->w_factor;
        m->borrowed = true;
        if (candidates == from->m->cand) {
            m->Wb = from->m->Wb;
        } else {
            // W's blocks between the candidates `from` has are its own; the columns of the others are made on the
            // tangent W was made on (K_W⁻¹ E_a, its rows at every candidate), their rows by symmetry: W stays that
            // tangent's inverse on the new candidates, positive definite. (Made on this tangent instead, the added
            // columns next to the old ones' made W indefinite: the tube's LCP failed on it.)
            if (!m->w_factor || from->m->nfree != mf)
                throw InputError("linearisation: borrowing a compliance on other candidates from a linearisation without its W's factor or with other fixed DOFs");
            const Eigen::Index nf = static_cast<Eigen::Index>(from->m->cand.size());
            std::vector<Eigen::Index> fslot(static_cast<size_t>(X.rows()), -1);
            for (Eigen::Index k = 0; k < nf; ++k) fslot[static_cast<size_t>(from->m->cand[static_cast<size_t>(k)])] = k;
            std::vector<Eigen::Index> old_at(static_cast<size_t>(ncand));
            std::vector<Eigen::Index> added;
            for (Eigen::Index k = 0; k < ncand; ++k) {
                old_at[static_cast<size_t>(k)] = fslot[static_cast<size_t>(candidates[static_cast<size_t>(k)])];
                if (old_at[static_cast<size_t>(k)] < 0) added.push_back(k);
            }
            added_candidates = static_cast<int>(added.size());
            auto Wb = std::make_shared<std::vector<double>>(static_cast<size_t>(nc) * static_cast<size_t>(nc), 0.0);
            const double* Wf = from->m->Wb->data();
            for (Eigen::Index b = 0; b < ncand; ++b) {
                const Eigen::Index fb = old_at[static_cast<size_t>(b)];
                if (fb < 0) continue;
                for (Eigen::Index a = 0; a < ncand; ++a) {
                    const Eigen::Index fa = old_at[static_cast<size_t>(a)];
                    if (fa < 0) continue;
                    std::copy_n(Wf + 9 * (static_cast<size_t>(fb) * static_cast<size_t>(nf) + static_cast<size_t>(fa)), 9,
                                Wb->data() + 9 * (static_cast<size_t>(b) * static_cast<size_t>(ncand) + static_cast<size_t>(a)));
                }
            }
            // The added DOFs' columns in blocks of 64 right-hand sides (a fixed DOF's column stays zero, as condense's)
            std::vector<std::pair<Eigen::Index, int>> cols;  // (candidate slot, axis) of each free added DOF
            for (Eigen::Index k : added)
                for (int ax = 0; ax < 3; ++ax)
                    if (m->free_index[static_cast<size_t>(3 * candidates[static_cast<size_t>(k)] + ax)] >= 0) cols.emplace_back(k, ax);
            constexpr Eigen::Index BLOCK = 64;
            for (size_t c0 = 0; c0 < cols.size() && mf > 0; c0 += BLOCK) {
                const Eigen::Index nb = static_cast<Eigen::Index>(std::min<size_t>(BLOCK, cols.size() - c0));
                Eigen::MatrixXd B = Eigen::MatrixXd::Zero(mf, nb);
                for (Eigen::Index j = 0; j < nb; ++j) {
                    const auto [k, ax] = cols[c0 + static_cast<size_t>(j)];
                    B(m->free_index[static_cast<size_t>(3 * candidates[static_cast<size_t>(k)] + ax)], j) = 1;
                }
                const Eigen::MatrixXd Y = m->w_factor->solve_columns(B);
                for (Eigen::Index j = 0; j < nb; ++j) {
                    const auto [k, ax] = cols[c0 + static_cast<size_t>(j)];
                    for (Eigen::Index a = 0; a < ncand; ++a)
                        for (int ai = 0; ai < 3; ++ai) {
                            const int fi = m->free_index[static_cast<size_t>(3 * candidates[static_cast<size_t>(a)] + ai)];
                            const double v = fi >= 0 ? Y(fi, j) : 0.0;
                            (*Wb)[9 * (static_cast<size_t>(k) * static_cast<size_t>(ncand) + static_cast<size_t>(a)) + 3 * static_cast<size_t>(ax) + static_cast<size_t>(ai)] = v;
                            (*Wb)[9 * (static_cast<size_t>(a) * static_cast<size_t>(ncand) + static_cast<size_t>(k)) + 3 * static_cast<size_t>(ai) + static_cast<size_t>(ax)] = v;
                        }
                }
            }
            m->Wb = std::move(Wb);
        }
        compliance_s += sw.lap();
        return;
    }
    m->w_u0 = std::make_shared<const Eigen::VectorXd>(u0);
    m->w_factor = m->factor;
    m->Wb->assign(static_cast<size_t>(nc) * static_cast<size_t>(nc), 0.0);
    if (!kept.empty() && mf > 0) {
        std::vector<Eigen::Index> slot(static_cast<size_t>(X.rows()), -1);
        for (size_t k = 0; k < candidates.size(); ++k) slot[static_cast<size_t>(candidates[k])] = static_cast<Eigen::Index>(k);
        const Eigen::Index M = cd.size();
        std::vector<Eigen::Index> at(static_cast<size_t>(M));  // W's row r: its place among the candidates' DOFs
        for (Eigen::Index r = 0; r < M; ++r) at[static_cast<size_t>(r)] = 3 * slot[static_cast<size_t>(cd.dof_node[r])] + cd.dof_axis[r];
        for (Eigen::Index c = 0; c < M; ++c) {
            const Eigen::Index j = at[static_cast<size_t>(c)];
            double* col = m->Wb->data() + 9 * (j / 3) * ncand + 3 * (j % 3);
            for (Eigen::Index r = 0; r < M; ++r) {
                const Eigen::Index i = at[static_cast<size_t>(r)];
                col[9 * (i / 3) + i % 3] = cd.W64(r, c);
            }
        }
    }
    compliance_s += sw.lap();
}

namespace {

/// The signed distance of p from the plane of triangle abc, positive on its normal's side ((b − a) × (c − a)); 0 for
/// a degenerate triangle.
double plane_distance(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
    const Eigen::Vector3d n = (b - a).cross(c - a);
    const double l = n.norm();
    return l > 0 ? n.dot(p - a) / l : 0.0;
}

}  // namespace

CompliantSetup compliant_setup(const ClipBlades& blades, double theta, const Eigen::MatrixX3d& x, const std::vector<int>& reach,
                               const Eigen::MatrixX3i& inner, double approach_mm, const Eigen::MatrixX3i& outer, const Eigen::MatrixX3d* rest) {
    CompliantClip one;
    one.blades = blades;
    one.theta = theta;
    return compliant_setup(std::vector<CompliantClip>{one}, x, reach, inner, approach_mm, outer, rest);
}

CompliantSetup compliant_setup(const std::vector<CompliantClip>& clips, const Eigen::MatrixX3d& x, const std::vector<int>& reach,
                               const Eigen::MatrixX3i& inner, double approach_mm, const Eigen::MatrixX3i& outer, const Eigen::MatrixX3d* rest) {
    if (clips.empty()) throw InputError("compliant setup: no clip");
    if (rest && rest->rows() != x.rows())
        throw InputError("compliant setup: a rest shape of " + std::to_string(rest->rows()) + " nodes for " + std::to_string(x.rows()));
    auto near_any = [&](const Eigen::Vector3d& p, double margin) {
        for (const CompliantClip& c : clips)
            if (c.blades.near_wedge(c.theta, p, margin)) return true;
        return false;
    };
    const Eigen::Index n = x.rows();
    auto check = [&](int a) {
        if (a < 0 || a >= n) throw InputError("compliant setup: node " + std::to_string(a) + " outside the body's " + std::to_string(n));
    };
    CompliantSetup out;
    std::vector<int> slot(static_cast<size_t>(n), -1);
    for (int a : reach) {
        check(a);
        if (slot[static_cast<size_t>(a)] < 0 && near_any(x.row(a).transpose(), 0.1)) {
            slot[static_cast<size_t>(a)] = static_cast<int>(out.candidates.size());
            out.candidates.push_back(a);
        }
    }
    out.blade_candidates = out.candidates.size();
    // The faces of one surface taken for the frames: with `wedge`, those whose corners lie within 0.3 mm of the jaws'
    // wedge (the lumen, which the blades flatten), and those about to meet (below).
    auto take_faces = [&](const Eigen::MatrixX3i& surface, bool wedge) {
        std::vector<Eigen::Index> near;
        for (Eigen::Index f = 0; f < surface.rows(); ++f) {
            bool in = wedge;
            for (int k = 0; k < 3; ++k) {
                check(surface(f, k));
                in = in && near_any(x.row(surface(f, k)).transpose(), 0.3);
            }
            if (in) near.push_back(f);
        }
        // The walls about to meet anywhere else (squeezed out beside or past the tips, session 46: C0001's 0.5 mm crossing
        // 2-6 mm past its 15 mm blades): a vertex within approach_mm in front of an opposite face (or a hair behind it),
        // one ring left out as the frames' wall search does; the face and the faces round the vertex become wall faces.
        if (approach_mm > 0 && surface.rows() > 0) {
            const size_t at_wedge = near.size();
            ContactParams cp;
            cp.search_mm = approach_mm;
            cp.exclude_rings = 1;
            // (With the rest shape, deeper too where the vertex came from the face's front: through it.)
            const std::vector<std::array<int, 2>> pairs = contact_pairs(x, surface, Eigen::VectorXd::Zero(3 * n), cp, rest ? WALL_THROUGH_MM : APPROACH_BEHIND_MM);
            std::vector<char> take(static_cast<size_t>(surface.rows()), 0), vert(static_cast<size_t>(n), 0);
            for (Eigen::Index f : near) take[static_cast<size_t>(f)] = 1;
            auto row = [](const Eigen::MatrixX3d& m, int a) { return Eigen::Vector3d(m.row(a).transpose()); };
            for (const auto& [v, f] : pairs) {
                const double d = signed_vertex_face_distance(row(x, v), row(x, surface(f, 0)), row(x, surface(f, 1)), row(x, surface(f, 2)));
                if (d > approach_mm) continue;
                // (Rest known) through the face only if in front of its plane at rest.
                if (d <= -APPROACH_BEHIND_MM && plane_distance(row(*rest, v), row(*rest, surface(f, 0)), row(*rest, surface(f, 1)), row(*rest, surface(f, 2))) <= 0)
                    continue;
                take[static_cast<size_t>(f)] = 1;
                vert[static_cast<size_t>(v)] = 1;
            }
            for (Eigen::Index f = 0; f < surface.rows(); ++f)
                if (!take[static_cast<size_t>(f)] &&
                    (vert[static_cast<size_t>(surface(f, 0))] || vert[static_cast<size_t>(surface(f, 1))] || vert[static_cast<size_t>(surface(f, 2))]))
                    take[static_cast<size_t>(f)] = 1;
            near.clear();
            for (Eigen::Index f = 0; f < surface.rows(); ++f)
                if (take[static_cast<size_t>(f)]) near.push_back(f);
            out.approach_faces += near.size() - at_wedge;
        }
        return near;
    };
    // The lumen's faces, then the outer surface's (only where it is about to meet itself: the blades press it, they
    // do not bring two parts of it together).
    const std::vector<Eigen::Index> from_inner = take_faces(inner, true), from_outer = take_faces(outer, false);
    out.faces.resize(static_cast<Eigen::Index>(from_inner.size() + from_outer.size()), 3);
    out.face_surface.assign(from_inner.size(), 0);
    out.face_surface.resize(from_inner.size() + from_outer.size(), 1);
    Eigen::Index row = 0;
    for (const auto& [surface, taken] : {std::pair<const Eigen::MatrixX3i*, const std::vector<Eigen::Index>*>{&inner, &from_inner}, {&outer, &from_outer}})
        for (Eigen::Index f : *taken) {
            for (int k = 0; k < 3; ++k) {
                const int a = (*surface)(f, k);
                int& sl = slot[static_cast<size_t>(a)];
                if (sl < 0) {
                    sl = static_cast<int>(out.candidates.size());
                    out.candidates.push_back(a);
                }
                out.faces(row, k) = sl;
            }
            ++row;
        }
    return out;
}

Linearisation::~Linearisation() = default;

const Eigen::VectorXd& Linearisation::u0() const { return m->u0; }
const Eigen::MatrixX3d& Linearisation::free_positions() const { return m->free_x; }
const Eigen::VectorXd& Linearisation::free_candidate_u() const { return m->free_u; }
const std::vector<int>& Linearisation::candidates() const { return m->cand; }
Eigen::Matrix3d Linearisation::compliance(int a, int b) const {
    const int n = static_cast<int>(m->cand.size());
    if (a < 0 || a >= n || b < 0 || b >= n)
        throw InputError("linearisation: compliance block (" + std::to_string(a) + ", " + std::to_string(b) + ") of " + std::to_string(n) + " candidates");
    return Eigen::Map<const Eigen::Matrix3d>(m->Wb->data() + 9 * (static_cast<size_t>(b) * static_cast<size_t>(n) + static_cast<size_t>(a)));
}
const double* Linearisation::compliance_blocks() const { return m->Wb->data(); }
bool Linearisation::borrowed() const { return m->borrowed; }
const Eigen::VectorXd& Linearisation::compliance_u0() const { return *m->w_u0; }
Eigen::VectorXd Linearisation::candidate_displacement(const Eigen::VectorXd& f) const {
    if (f.size() == 3 * static_cast<Eigen::Index>(m->cand.size()) && f.isZero(0.0)) return m->free_u;
    const Eigen::VectorXd u = displacement(f);
    Eigen::VectorXd out(3 * static_cast<Eigen::Index>(m->cand.size()));
    for (size_t k = 0; k < m->cand.size(); ++k) out.segment<3>(3 * static_cast<Eigen::Index>(k)) = u.segment<3>(3 * static_cast<Eigen::Index>(m->cand[k]));
    return out;
}

Eigen::VectorXd Linearisation::displacement(const Eigen::VectorXd& f) const {
    if (f.size() != 3 * static_cast<Eigen::Index>(m->cand.size()))
        throw InputError("linearisation: " + std::to_string(f.size()) + " candidate forces, expected " + std::to_string(3 * m->cand.size()));
    // No force on any candidate (the blades closing through the air): the free state, kept from the constructor's
    // solve, the same numbers (the sample's patch: a 20-30 ms back substitution a frame, most of an air frame's time).
    if (f.isZero(0.0)) return m->free_body_u;
    Eigen::VectorXd rhs = m->r0;
    for (size_t k = 0; k < m->cand.size(); ++k)
        for (int ax = 0; ax < 3; ++ax)
            if (const int a = m->free_index[static_cast<size_t>(3 * m->cand[k] + ax)]; a >= 0) rhs[a] += f[static_cast<Eigen::Index>(3 * k) + ax];
    Eigen::VectorXd u = m->u0;
    if (m->nfree == 0) return u;
    const Eigen::VectorXd du = m->solve(rhs);
    for (Eigen::Index i = 0; i < u.size(); ++i)
        if (const int a = m->free_index[static_cast<size_t>(i)]; a >= 0) u[i] += du[a];
    return u;
}

namespace {

/// blade_distance with its derivatives: on the point (grad) and on the opening θ (dtheta).
double blade_distance_d(const ClipBlades& b, int s, double theta, const Eigen::Vector3d& x, Eigen::Vector3d* grad, double* dtheta) {
    // ClipBody::blade_distance's geometry: the blade is the set within ρ of its core, the rectangle r ∈ [0, L − ρ],
    // |a| ≤ W/2 − ρ at ρ behind the face; over the core the plane's distance, beside it the distance to the core's
    // edge (the height above the core's plane counted only in front of it). As θ grows the blade turns by θ/2:
    // ∂n/∂θ = t/2, ∂t/∂θ = −n/2.
    const double rho = std::min({0.1, 0.5 * b.thickness_mm, 0.25 * b.width_mm, 0.25 * b.length_mm});
    Eigen::Vector3d t, n, w;
    b.frame(s, theta, t, n, w);
    const Eigen::Vector3d rel = x - b.hinge;
    const double r = rel.dot(t), a = rel.dot(w), qn = rel.dot(n), p = 0.5 * b.closed_gap_mm + qn;
    const double half = 0.5 * b.width_mm - rho, tip = b.length_mm - rho;
    // A curved blade: the same in its face coordinates (ClipBlades::face_coords: s along its centre line, c across).
    const ClipBlades::FaceCoords fc = b.face_coords(r, a);
    const double vr = fc.s - std::clamp(fc.s, b.core_from(rho, tip), tip), va = fc.a - std::clamp(fc.a, -half, half);
    if (vr == 0 && va == 0) {
        if (grad) *grad = n;
        if (dtheta) *dtheta = 0.5 * r;
        return p;
    }
    const double vd = std::max(p + rho, 0.0), dist = std::sqrt(vr * vr + va * va + vd * vd);
    if (!b.curved()) {
        if (grad) *grad = (vr * t + va * w + vd * n) / dist;  // vd = 0 where p + ρ ≤ 0: no term
        if (dtheta) *dtheta = (vr * (-0.5 * qn) + vd * 0.5 * r) / dist;
        return dist - rho;
    }
    // ∇s = s_r t + s_a w, ∂s/∂θ = s_r ∂r/∂θ = −s_r q/2 (a's alike): r turns with the blade, a does not.
    const double cr = vr * fc.ds[0] + va * fc.da[0], ca = vr * fc.ds[1] + va * fc.da[1];
    if (grad) *grad = (cr * t + ca * w + vd * n) / dist;
    if (dtheta) *dtheta = (cr * (-0.5 * qn) + vd * 0.5 * r) / dist;
    return dist - rho;
}

}  // namespace

double blade_distance(const ClipBlades& b, int s, double theta, const Eigen::Vector3d& x) {
    return blade_distance_d(b, s, theta, x, nullptr, nullptr);
}

namespace {

/// A dense n x n matrix in a buffer the thread keeps: the frames' Delassus matrices and their active rows' factors
/// (35 MB each at the sample's 2,100 rows) were allocated afresh in every pass, each a fresh mapping whose pages the
/// kernel zeroed on first touch (a tenth of the pressed frames' time). Its contents are undefined.
Eigen::Map<Eigen::MatrixXd> scratch_square(std::vector<double>& buf, Eigen::Index n) {
    const size_t need = static_cast<size_t>(n) * static_cast<size_t>(n);
    if (buf.size() < need) buf.resize(need);
    return Eigen::Map<Eigen::MatrixXd>(buf.data(), n, n);
}
std::vector<double>& factor_scratch() {
    thread_local std::vector<double> buf;
    return buf;
}
std::vector<double>& delassus_scratch() {
    thread_local std::vector<double> buf;
    return buf;
}

/// The Cholesky factor L Lᵀ = A_SS of the active rows S of an SPD matrix, kept as the pivoting flips rows in and out:
/// a row taken in is appended (a forward substitution, O(|S|²)), a row let go is cut out and the factor below it
/// mended by a rank-one update (O(|S|²)); many flips at once, or an append whose pivot has lost its digits (nearly
/// redundant rows), factorise A_SS afresh (O(|S|³)).
class ActiveFactor {
public:
    explicit ActiveFactor(const Eigen::Ref<const Eigen::MatrixXd>& A)
        : A_(A), L_(scratch_square(factor_scratch(), A.rows())), pos_(static_cast<size_t>(A.rows()), -1) {}

    /// Factorise A_SS afresh for the rows marked in `act`, in index order.
    void refactor(const std::vector<char>& act) {
        S_.clear();
        std::fill(pos_.begin(), pos_.end(), -1);
        for (Eigen::Index i = 0; i < A_.rows(); ++i)
            if (act[static_cast<size_t>(i)]) {
                pos_[static_cast<size_t>(i)] = static_cast<Eigen::Index>(S_.size());
                S_.push_back(i);
            }
        const Eigen::Index ns = size();
        // A_SS's lower triangle gathered into L's place and factorised there by LAPACK (OpenBLAS's blocked kernels:
        // on the sample's friction frames, ~1,200 active rows, Eigen's LLT was a third of a frame's time).
        for (Eigen::Index c = 0; c < ns; ++c) {
            const double* Ac = A_.col(S_[static_cast<size_t>(c)]).data();
            for (Eigen::Index a = c; a < ns; ++a) L_(a, c) = Ac[S_[static_cast<size_t>(a)]];
        }
        if (ns > 0) {
            const int n = static_cast<int>(ns), lda = static_cast<int>(L_.rows());
            int info = 0;
            dpotrf_("L", &n, L_.data(), &lda, &info);
            // SPD: the compliance is, and every row has its mixing; a failure is a numerical fault of the frame
            if (info != 0) throw NumericalError("lcp: the active rows' matrix is not positive definite (dpotrf info " + std::to_string(info) + ")");
        }
        ++refactors;
        updates = 0;
    }
    /// Take row i in. False where its pivot came out at or below 10⁻¹² of its diagonal: the caller factorises afresh.
    bool append(Eigen::Index i) {
        const Eigen::Index ns = size();
        Eigen::VectorXd l(ns);
        for (Eigen::Index a = 0; a < ns; ++a) l[a] = A_(S_[static_cast<size_t>(a)], i);
        if (ns > 0) L_.topLeftCorner(ns, ns).triangularView<Eigen::Lower>().solveInPlace(l);
        const double d2 = A_(i, i) - l.squaredNorm();
        if (!(d2 > 1e-12 * A_(i, i))) return false;
        L_.row(ns).head(ns) = l.transpose();
        L_(ns, ns) = std::sqrt(d2);
        pos_[static_cast<size_t>(i)] = ns;
        S_.push_back(i);
        ++updates;
        return true;
    }
    /// Let row i go: its row and column cut out of L, the block below mended by the rank-one update that the cut
    /// column carried.
    void remove(Eigen::Index i) {
        const Eigen::Index k = pos_[static_cast<size_t>(i)], ns = size(), r = ns - k - 1;
        Eigen::VectorXd x = L_.col(k).segment(k + 1, r);
        for (Eigen::Index c = 0; c < k; ++c)  // columns left of it: their rows below it move up
            for (Eigen::Index a = k; a < ns - 1; ++a) L_(a, c) = L_(a + 1, c);
        for (Eigen::Index c = k; c < ns - 1; ++c)  // the block below and right of it moves up and left
            for (Eigen::Index a = c; a < ns - 1; ++a) L_(a, c) = L_(a + 1, c + 1);
        // L₂₂' L₂₂'ᵀ = L₂₂ L₂₂ᵀ + x xᵀ (the update of LINPACK's dchud, column by column)
        for (Eigen::Index j = 0; j < r; ++j) {
            const Eigen::Index c = k + j;
            const double ljj = L_(c, c), rr = std::hypot(ljj, x[j]), cs = rr / ljj, sn = x[j] / ljj;
            L_(c, c) = rr;
            const Eigen::Index rest = r - j - 1;
            if (rest > 0) {
                L_.col(c).segment(c + 1, rest) = (L_.col(c).segment(c + 1, rest) + sn * x.segment(j + 1, rest)) / cs;
                x.segment(j + 1, rest) = cs * x.segment(j + 1, rest) - sn * L_.col(c).segment(c + 1, rest);
            }
        }
        S_.erase(S_.begin() + k);
        pos_[static_cast<size_t>(i)] = -1;
        ++updates;
        for (Eigen::Index a = k; a < size(); ++a) pos_[static_cast<size_t>(S_[static_cast<size_t>(a)])] = a;
    }
    /// z with z_S = −A_SS⁻¹ q_S and 0 elsewhere.
    Eigen::VectorXd solve(const Eigen::VectorXd& q) const {
        const Eigen::Index ns = size();
        Eigen::VectorXd y(ns);
        for (Eigen::Index a = 0; a < ns; ++a) y[a] = -q[S_[static_cast<size_t>(a)]];
        const auto L = L_.topLeftCorner(ns, ns).triangularView<Eigen::Lower>();
        L.solveInPlace(y);
        L.transpose().solveInPlace(y);
        Eigen::VectorXd z = Eigen::VectorXd::Zero(q.size());
        for (Eigen::Index a = 0; a < ns; ++a) z[S_[static_cast<size_t>(a)]] = y[a];
        return z;
    }
    Eigen::Index size() const { return static_cast<Eigen::Index>(S_.size()); }
    const std::vector<Eigen::Index>& rows() const { return S_; }
    int refactors = 0;
    int updates = 0;  ///< rows appended or removed since the last factorisation from scratch (round-off accumulates)

private:
    const Eigen::Ref<const Eigen::MatrixXd> A_;
    Eigen::Map<Eigen::MatrixXd> L_;     // lower, its leading |S| x |S| in use (the thread's scratch)
    std::vector<Eigen::Index> S_;       // the active rows in the factor's order
    std::vector<Eigen::Index> pos_;     // per row: its place in S_, -1 out
};

}  // namespace

LcpResult solve_box_lcp(const Eigen::Ref<const Eigen::MatrixXd>& A, const Eigen::VectorXd& q, const Eigen::VectorXd& lo, const Eigen::VectorXd& hi, Eigen::VectorXd& z,
                        const LcpOptions& opt) {
    const Eigen::Index mz = q.size();
    if (A.rows() != mz || A.cols() != mz || z.size() != mz || lo.size() != mz || hi.size() != mz)
        throw InputError("lcp: a " + std::to_string(A.rows()) + " x " + std::to_string(A.cols()) + " matrix, " + std::to_string(q.size()) + " constants, " +
                         std::to_string(lo.size()) + " and " + std::to_string(hi.size()) + " bounds and " + std::to_string(z.size()) + " unknowns do not match");
    for (Eigen::Index i = 0; i < mz; ++i)
        if (!(lo[i] <= hi[i]) || lo[i] == std::numeric_limits<double>::infinity() || hi[i] == -std::numeric_limits<double>::infinity())
            throw InputError("lcp: row " + std::to_string(i) + " has bounds [" + std::to_string(lo[i]) + ", " + std::to_string(hi[i]) + "]: expected lo <= hi, lo < inf, hi > -inf");
    z = z.cwiseMax(lo).cwiseMin(hi);
    // Projected Gauss–Seidel from z, keeping w = q + A z up to date.
    Eigen::VectorXd w = q + A * z;
    LcpResult out;
    // How far a row is off, in the rows' units (the clip's stop: rad): at its lower bound w must be ≥ 0, at its upper
    // bound ≤ 0, between them 0; a row whose bounds meet is held there, whatever its w.
    auto off = [&](Eigen::Index i, double zi, double wi) {
        if (zi <= lo[i] && zi >= hi[i]) return 0.0;
        return zi <= lo[i] ? std::max(0.0, -wi) : zi >= hi[i] ? std::max(0.0, wi) : std::abs(wi);
    };
    auto violation = [&] {
        double v = 0;
        for (Eigen::Index i = 0; i < mz; ++i) v = std::max(v, off(i, z[i], w[i]));
        return v;
    };
    auto sweep_once = [&] {  // one projected Gauss–Seidel sweep
        for (Eigen::Index i = 0; i < mz; ++i) {
            if (!(A(i, i) > 0)) continue;
            const double zi = std::clamp(z[i] - w[i] / A(i, i), lo[i], hi[i]), dz = zi - z[i];
            if (dz != 0) {
                w.noalias() += dz * A.col(i);
                z[i] = zi;
            }
        }
        return violation();
    };
    int sweep = 0;
    double viol = violation();
    while (sweep < opt.max_sweeps && viol > opt.tolerance) {
        viol = sweep_once();
        ++sweep;
    }
    out.sweeps = sweep;
    // The sweeps converge slowly where θ couples every row (a released clip); finish by block principal pivoting
    // from the sweeps' active set: solve the free rows exactly (the others held at their bounds), move every free row
    // that came out beyond a bound to it and every bounded row whose w points into its range free, repeat. Flipping
    // every such row at once can cycle (the sample's pressed walls: nearly redundant rows); Júdice & Pires (1994)'s
    // safeguard: when the count of such rows has not fallen for 3 solves, flip only the last of them (Murty's rule,
    // finite for the P-matrix that A is with its mixing) until it falls below the best count again. Kept only where
    // it does better than the sweeps.
    if (viol > opt.tolerance && mz > 0) {
        enum : char { LOW = 0, FREE = 1, HIGH = 2 };
        std::vector<char> state(static_cast<size_t>(mz)), act(static_cast<size_t>(mz));
        for (Eigen::Index i = 0; i < mz; ++i) {
            const bool at_lo = z[i] <= lo[i], at_hi = z[i] >= hi[i];
            state[static_cast<size_t>(i)] = lo[i] == hi[i] ? LOW  // held at its bounds: never free
                                            : (!at_lo && !at_hi) || (at_lo && w[i] < 0) || (at_hi && w[i] > 0) ? FREE
                                            : at_lo ? LOW : HIGH;
            act[static_cast<size_t>(i)] = state[static_cast<size_t>(i)] == FREE;
        }
        size_t best_count = std::numeric_limits<size_t>::max();
        int tries = 3;
        ActiveFactor F(A);
        F.refactor(act);
        for (int it = 0; it < opt.max_pivots; ++it) {
            // The rows at a bound (other than 0) move the free rows' right-hand side.
            Eigen::VectorXd qb = q, zt = Eigen::VectorXd::Zero(mz);
            for (Eigen::Index i = 0; i < mz; ++i)
                if (const char st = state[static_cast<size_t>(i)]; st != FREE) {
                    zt[i] = st == LOW ? lo[i] : hi[i];
                    if (zt[i] != 0) qb.noalias() += zt[i] * A.col(i);
                }
            const Eigen::VectorXd zf = F.solve(qb);
            Eigen::VectorXd wt = qb;  // q + A zt, through the free columns
            for (Eigen::Index i : F.rows()) {
                zt[i] = zf[i];
                wt.noalias() += zt[i] * A.col(i);
            }
            std::vector<Eigen::Index> wrong;
            for (Eigen::Index i = 0; i < mz; ++i) {
                const char st = state[static_cast<size_t>(i)];
                if (lo[i] == hi[i]) continue;
                if ((st == FREE && (zt[i] < lo[i] - opt.tolerance * 1e-3 || zt[i] > hi[i] + opt.tolerance * 1e-3)) || (st == LOW && wt[i] < -opt.tolerance) ||
                    (st == HIGH && wt[i] > opt.tolerance))
                    wrong.push_back(i);
            }
            out.pivots = it + 1;
            if (wrong.empty()) {
                const Eigen::VectorXd zc = zt.cwiseMax(lo).cwiseMin(hi), wc = q + A * zc;
                double v = 0;
                for (Eigen::Index i = 0; i < mz; ++i) v = std::max(v, off(i, zc[i], wc[i]));
                if (v < viol) {
                    z = zc;
                    w = wc;
                    viol = v;
                }
                break;
            }
            if (wrong.size() < best_count) {
                best_count = wrong.size();
                tries = 3;
            } else if (tries > 0) {
                --tries;
            } else {
                wrong = {wrong.back()};
                ++out.single_pivots;
            }
            for (Eigen::Index i : wrong) {
                char& st = state[static_cast<size_t>(i)];
                st = st != FREE ? FREE : zt[i] < lo[i] ? LOW : HIGH;
                act[static_cast<size_t>(i)] = st == FREE;
            }
            // The factor follows: row by row where few flip (each O(|S|²)), afresh where many do (O(|S|³)) or an
            // appended row's pivot lost its digits.
            bool fresh = 8 * wrong.size() > static_cast<size_t>(F.size()) + 8 || F.updates > 64;
            if (!fresh) {
                for (Eigen::Index i : wrong)
                    if (!act[static_cast<size_t>(i)]) F.remove(i);
                for (Eigen::Index i : wrong)
                    if (act[static_cast<size_t>(i)] && !F.append(i)) {
                        fresh = true;
                        break;
                    }
            }
            if (fresh) F.refactor(act);
        }
        out.refactors = F.refactors;
    }
    // Pivoting that cycled or stalled (redundant rows: a vertex pressed on two faces of an edge): more sweeps from
    // the best so far, until the gaps are off by no more than opt.accept.
    for (int extra = 0; viol > opt.accept && extra < 100; ++extra) {
        viol = sweep_once();
        ++out.sweeps;
    }
    out.violation = viol;
    return out;
}

LcpResult solve_lcp(const Eigen::Ref<const Eigen::MatrixXd>& A, const Eigen::VectorXd& q, Eigen::VectorXd& z, const LcpOptions& opt) {
    return solve_box_lcp(A, q, Eigen::VectorXd::Zero(q.size()), Eigen::VectorXd::Constant(q.size(), std::numeric_limits<double>::infinity()), z, opt);
}

namespace {


/// Whether a wall pair (vertex, then its face's corners, candidate numbering) whose vertex stands `start_d` from its
/// face's plane where the frame starts is a crease, no constraint: behind that plane by more than wall_behind_mm, and
/// behind it at rest too (walls.rest; none known: taken as behind) or behind it now by more than wall_through_mm (the
/// far side of a fold). Otherwise the frame pushes the vertex back out.
bool is_crease(const CompliantWalls& walls, const std::array<int, 4>& k, double start_d, const CompliantOptions& opt) {
    if (start_d >= -opt.wall_behind_mm) return false;
    if (walls.rest.rows() == 0 || start_d < -opt.wall_through_mm) return true;
    auto at = [&](int a) { return Eigen::Vector3d(walls.rest.row(k[static_cast<size_t>(a)]).transpose()); };
    return plane_distance(at(0), at(1), at(2), at(3)) < -opt.wall_behind_mm;
}

/// A wall pair's vertex p over its face abc: the face's unit normal nh ((b − a) × (c − a)), p's signed distance d from
/// the face's plane and its projection's barycentric coordinates b. A pair is a contact where the vertex lies over
/// the face: its projection inside it, or within a tenth of the face beyond an edge (OVER); the distance to the closed
/// triangle, ≥ 0 beside it, would let a vertex pressed to an edge slide round it and under the face, and beyond the
/// tenth its neighbour's pair holds it. One rule for the frames' rows and their measure (wall_min_distance).
struct OverFace {
    Eigen::Vector3d nh;
    double d = 0, b0 = 0, b1 = 0, b2 = 0;
};
/// `over`: the margin beyond the edges (OVER_FACE; a row the vertex had in the last pass keeps it to OVER_KEPT below).
constexpr double OVER_FACE = -0.1;
bool over_face(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c, OverFace& o,
               double OVER = OVER_FACE) {
    const Eigen::Vector3d e1 = b - a, e2 = c - a, nn = e1.cross(e2);
    const double area2 = nn.norm();
    if (!(area2 > 0)) return false;
    const Eigen::Vector3d w = p - a;
    o.nh = nn / area2;
    const double d11 = e1.dot(e1), d12 = e1.dot(e2), d22 = e2.dot(e2), w1 = w.dot(e1), w2 = w.dot(e2), den = d11 * d22 - d12 * d12;
    o.b1 = (d22 * w1 - d12 * w2) / den;
    o.b2 = (d11 * w2 - d12 * w1) / den;
    o.b0 = 1 - o.b1 - o.b2;
    o.d = o.nh.dot(w);
    return o.b0 >= OVER && o.b1 >= OVER && o.b2 >= OVER;
}

/// u += W f, over the candidates `which` (each once; their order is the sums' order).
void add_compliance_times(const Linearisation& lin, const Eigen::VectorXd& f, const std::vector<int>& which, Eigen::VectorXd& u) {
    const double* Wb = lin.compliance_blocks();
    const auto nc = static_cast<size_t>(lin.candidates().size());
    for (const int c : which) {
        const Eigen::Vector3d fc = f.segment<3>(3 * c);
        if (fc.squaredNorm() == 0) continue;
        for (size_t a = 0; a < nc; ++a)
            u.segment<3>(3 * static_cast<Eigen::Index>(a)).noalias() += Eigen::Map<const Eigen::Matrix3d>(Wb + 9 * (static_cast<size_t>(c) * nc + a)) * fc;
    }
}

/// One pass of a frame: the constraints linearised where `warm` left the candidates (else at the free state), those
/// behind a blade or a wall where the frame started (`start`: the candidates' displacement there) left out.
CompliantFrame solve_pass(const Linearisation& lin, const ClipBlades& blades, const ClipSpring& spring, std::optional<double> theta_held,
                          double theta_start, const CompliantFrame* warm, const CompliantOptions& opt, const CompliantWalls* walls,
                          const Eigen::VectorXd& start, const std::vector<CompliantClip>* more, const Eigen::VectorXd* free_u = nullptr,
                          const std::set<std::pair<int, int>>* held = nullptr) {
    const Stopwatch sw;
    if (!(spring.k_nmm_per_rad > 0) || !(spring.preload_rad >= 0)) throw InputError("compliant clip: the spring needs k > 0 and a preload >= 0");
    if (theta_held && !(*theta_held >= 0)) throw InputError("compliant clip: the held opening must be >= 0 rad");
    const double theta_ref = theta_held ? *theta_held : std::max(theta_start, 0.0);
    // The free state: the linearisation's, or (a borrowed W's later passes) the one that puts the last pass's exact end
    // at its forces on this W: what the passes' gaps are linearised from (free_u, else lin.free_candidate_u()).
    Eigen::MatrixX3d Xf_moved;
    if (free_u) {
        Xf_moved = lin.free_positions();
        for (Eigen::Index k = 0; k < Xf_moved.rows(); ++k) Xf_moved.row(k) += (free_u->segment<3>(3 * k) - lin.free_candidate_u().segment<3>(3 * k)).transpose();
    }
    const Eigen::MatrixX3d& Xf = free_u ? Xf_moved : lin.free_positions();
    const Eigen::Index nc = Xf.rows();
    const double* Wb = lin.compliance_blocks();
    auto Wblock = [&](int a, int b) {
        return Eigen::Map<const Eigen::Matrix3d>(Wb + 9 * (static_cast<size_t>(b) * static_cast<size_t>(nc) + static_cast<size_t>(a)));
    };

    // The constraints: every candidate within reach of a blade (and not behind it: tissue beside or behind a blade
    // stays there), and every wall pair within reach, linearised where the candidates are: gap d, gradient g on the
    // positions of its candidates (one for a blade, the vertex and the face's three for a wall pair), b on θ.
    struct Row {
        int n = 1;                         // candidates in the row
        std::array<int, 4> k{0, 0, 0, 0};  // which (a friction cell's: its first; all of them in kx)
        int s = 1;                         // its kind (compliant_row_kind): a blade's, a wall pair's (2 + face), a friction row's
        int clip = 0;                      // a blade or friction row's clip (0: the first; its θ may be free)
        double d = 0, b = 0;
        std::array<Eigen::Vector3d, 4> g;
        double lo = 0, hi = std::numeric_limits<double>::infinity();  // its force's bounds (friction rows: ±μ λ_n)
        std::vector<int> kx;               // a friction cell's candidates (n of them), else empty
        std::vector<Eigen::Vector3d> gx;   // and its gradient on each
        int cand(int a) const { return kx.empty() ? k[static_cast<size_t>(a)] : kx[static_cast<size_t>(a)]; }
        const Eigen::Vector3d& grad(int a) const { return gx.empty() ? g[static_cast<size_t>(a)] : gx[static_cast<size_t>(a)]; }
    };
    std::vector<Row> rows;
    constexpr double BEHIND = 0.02;
    const bool free_theta = !theta_held;
    // A released clip closes at most max_closing_rad in one frame (θ ≥ θ_lo): the frames approach the balance
    // of spring and tissue, each linearising the blades where the last one left them.
    const double theta_lo = free_theta ? std::max(0.0, theta_ref - opt.max_closing_rad) : theta_ref;
    // The clips: the first (θ free or held) and the further ones (CompliantClip), held; each blade of clip c is slot
    // 2c + side (side 0: blade +1, 1: blade −1).
    struct ClipAt {
        const ClipBlades* b = nullptr;
        double theta = 0, start = 0;  // this frame's opening, the last frame's
    };
    std::vector<ClipAt> clip_at{ClipAt{&blades, theta_ref, std::max(theta_start, 0.0)}};
    if (more)
        for (const CompliantClip& c : *more) {
            if (!(c.theta >= 0)) throw InputError("compliant clip: a further clip's opening must be >= 0 rad");
            clip_at.push_back(ClipAt{&c.blades, c.theta, std::max(c.theta_start, 0.0)});
        }
    const size_t ncl = clip_at.size();
    // The gaps are linearised where the candidates are: where the last frame left them (on this linearisation or
    // an older one), else at the free state. A candidate's position for forces f is free + W f, so a gap is
    // d(x_last) + Σ g · (free + W f − x_last).
    const bool from_last = warm && warm->candidate_u.size() == 3 * nc;
    const Eigen::VectorXd& fu = free_u ? *free_u : lin.free_candidate_u();
    Eigen::MatrixX3d Xl = Xf;  // where the gaps are linearised
    if (from_last)
        for (Eigen::Index k = 0; k < nc; ++k) Xl.row(k) += (warm->candidate_u.segment<3>(3 * k) - fu.segment<3>(3 * k)).transpose();
    Eigen::MatrixX3d Xs = Xf;  // where the frame started
    for (Eigen::Index k = 0; k < nc; ++k) Xs.row(k) += (start.segment<3>(3 * k) - fu.segment<3>(3 * k)).transpose();
    // Friction (opt.blade_friction): a candidate the last pass or frame pressed on a blade with normal force
    // λ_n is held where it stood on that blade when the frame started (carried by the blade's turn since), by tangential
    // rows whose forces stay within ±μ λ_n (Coulomb's box; λ_n from the last pass: the passes iterate on it).
    // With opt.friction_cell_mm > 0 the pressed candidates of a blade are gathered in square cells of the blade's face
    // (by where they stood at the frame's start), two rows a cell: the slip of the cell's candidates, each weighted by
    // its share w_k = λ_k / Λ of the cell's normal force Λ, is zero, the row's force z within ±μ Λ. Its force on
    // candidate k is z w_k, so each candidate's friction stays within its own ±μ λ_k; what the cell gives up is the
    // candidates' slips relative to one another (each node its own cell: friction_cell_mm = 0).
    // Not followed: the hinge's own motion within the frame (the stick point turns with the blade about where the hinge
    // is now), and the friction forces' small moment about the hinge (the loads' moment is the normal forces').
    std::map<std::pair<int, int>, double> pressed;
    if (opt.blade_friction > 0 && warm)
        for (size_t i = 0; i < warm->constraint.size() && i < warm->lambda.size(); ++i)
            if (compliant_row_kind(warm->constraint[i].second).blade && warm->lambda[i] > 0) pressed[warm->constraint[i]] = warm->lambda[i];
    struct Cell {
        int slot = 0;                       // 2 clip + side (side 0: blade +1, 1: blade −1)
        std::vector<int> nodes;
        std::vector<double> lambda;
        std::vector<Eigen::Vector3d> stick;
    };
    std::vector<Cell> cells;
    std::map<std::array<long long, 3>, size_t> cell_of;
    // Per blade slot its directions along, normal to and across it where the frame started (0) and now.
    std::vector<Eigen::Vector3d> ft0(2 * ncl), fn0(2 * ncl), fw0(2 * ncl), ft(2 * ncl), fn(2 * ncl), fw(2 * ncl);
    for (size_t c = 0; c < ncl; ++c)
        for (int side = 0; side < 2; ++side) {
            const int s = side == 0 ? 1 : -1;
            const size_t i = 2 * c + static_cast<size_t>(side);
            clip_at[c].b->frame(s, clip_at[c].start, ft0[i], fn0[i], fw0[i]);
            clip_at[c].b->frame(s, clip_at[c].theta, ft[i], fn[i], fw[i]);
        }
    for (Eigen::Index k = 0; k < nc; ++k) {
        const Eigen::Vector3d x = Xl.row(k).transpose();
        for (size_t c = 0; c < ncl; ++c)
            for (int side = 0; side < 2; ++side) {
                const ClipAt& ca = clip_at[c];
                const int sg = side == 0 ? 1 : -1;  // the blade, geometrically
                if (blade_distance(*ca.b, sg, ca.start, Xs.row(k).transpose()) < -BEHIND) continue;  // behind where the blade was
                Row r;
                const double d = blade_distance_d(*ca.b, sg, ca.theta, x, &r.g[0], &r.b);
                const double d_lo = free_theta && c == 0 ? d - r.b * (theta_ref - theta_lo) : d;
                if (std::min(d, d_lo) >= opt.reach_mm) continue;
                if (r.g[0].squaredNorm() < 0.25) continue;  // no direction to push (a point on the core's edge line)
                r.k[0] = static_cast<int>(k);
                r.s = compliant_blade_row(static_cast<int>(c), side);
                r.clip = static_cast<int>(c);
                r.d = d + r.g[0].dot(Xf.row(k).transpose() - x);
                rows.push_back(r);
                if (const auto it = pressed.find({static_cast<int>(k), r.s}); it != pressed.end()) {
                    const int slot = 2 * static_cast<int>(c) + side;
                    const size_t i = static_cast<size_t>(slot);
                    const Eigen::Vector3d& t0 = ft0[i];
                    const Eigen::Vector3d& w0 = fw0[i];
                    const Eigen::Vector3d rel = Xs.row(k).transpose() - ca.b->hinge;
                    const Eigen::Vector3d stick = ca.b->hinge + rel.dot(t0) * ft[i] + rel.dot(w0) * fw[i] + rel.dot(fn0[i]) * fn[i];
                    const double h = opt.friction_cell_mm;
                    const std::array<long long, 3> key = h > 0 ? std::array<long long, 3>{slot, static_cast<long long>(std::floor(rel.dot(t0) / h)), static_cast<long long>(std::floor(rel.dot(w0) / h))}
                                                               : std::array<long long, 3>{slot, static_cast<long long>(k), 0};
                    auto [pos, fresh] = cell_of.try_emplace(key, cells.size());
                    if (fresh) cells.push_back(Cell{slot, {}, {}, {}});
                    Cell& cl = cells[pos->second];
                    cl.nodes.push_back(static_cast<int>(k));
                    cl.lambda.push_back(it->second);
                    cl.stick.push_back(stick);
                }
            }
    }
    for (const Cell& c : cells) {
        double total = 0;
        for (double l : c.lambda) total += l;
        for (int dir = 0; dir < 2; ++dir) {
            const Eigen::Vector3d& e = dir == 0 ? ft[static_cast<size_t>(c.slot)] : fw[static_cast<size_t>(c.slot)];
            Row fr;
            fr.n = static_cast<int>(c.nodes.size());
            fr.k[0] = c.nodes[0];
            fr.clip = c.slot / 2;
            fr.s = compliant_friction_row(c.slot / 2, c.slot % 2, dir);
            fr.kx = c.nodes;
            fr.d = 0;
            for (size_t a = 0; a < c.nodes.size(); ++a) {
                fr.gx.push_back(c.lambda[a] / total * e);
                fr.d += fr.gx.back().dot(Xf.row(c.nodes[a]).transpose() - c.stick[a]);  // the weighted slip from the stick points, linear in the motion
            }
            fr.g[0] = fr.gx[0];
            fr.lo = -opt.blade_friction * total;
            fr.hi = opt.blade_friction * total;
            rows.push_back(std::move(fr));
        }
    }
    int wall_rows = 0;
    double wall_min = std::numeric_limits<double>::infinity();
    if (walls) {
        // With opt.wall_one_face, per vertex only its best row: of its faces within 0.02 mm of the nearest, the one its
        // projection lies deepest inside (the largest smallest barycentric coordinate), unless the face its row had in
        // `warm` (the last pass, or the last frame) is still one of them: a vertex over the edge between two faces
        // then keeps its face. (Without it the sample's held walls chattered: a vertex over an edge took one face in a
        // pass, moved 6 µm along its plane, took the other in the next and moved back, with six others, so the
        // geometry passes never settled and every frame ended on one of two states.)
        std::vector<std::pair<double, double>> score;  // per kept wall row: (d, inside), when filtering
        const size_t wall_start = rows.size();
        // The faces of each vertex's rows in `warm` (2 + f; at most two a vertex, below). A vertex pressed on a face
        // near its edge slides along it within a pass; where it ends a little beyond the edge (beyond OVER_FACE),
        // over no face of its pairs (the wedge above a ridge) or over the neighbour only, the next pass had no row on
        // that face and took it back through it: the sample's held clip, 0.04-0.17 mm behind a face in a frame's
        // last pass, every time after its pass before had ended 0.12-0.24 of the face beyond that edge (session 44,
        // ANEU_WALL_TRACE). So a face a vertex's row had in `warm` stays its row while the vertex lies within
        // OVER_KEPT of the face (hysteresis; at 0.3 some slid on to 0.31 and back through, the rows' push along the
        // normal carrying them sideways through the shell's compliance). Beyond an edge the face's plane holds the
        // vertex as far out as the surface or further: beyond a ridge, out by at most the slide times the ridge's
        // slope (the sample: 0.025 mm at most); beyond a valley the neighbour's row is the stricter.
        constexpr double OVER_KEPT = -0.5;
        std::vector<std::array<int, 2>> had(static_cast<size_t>(nc), std::array<int, 2>{-1, -1});
        if (warm)
            for (const auto& [v, sf] : warm->constraint)
                if (sf >= 2 && v >= 0 && v < nc) {
                    auto& h = had[static_cast<size_t>(v)];
                    (h[0] < 0 ? h[0] : h[1]) = sf;
                }
        for (const auto& [v, f] : walls->pairs) {
            if (v < 0 || v >= nc || f < 0 || f >= walls->faces.rows())
                throw InputError("compliant clip: wall pair (" + std::to_string(v) + ", " + std::to_string(f) + ") outside the candidates or faces");
            Row r;
            r.n = 4;
            r.k = {v, walls->faces(f, 0), walls->faces(f, 1), walls->faces(f, 2)};
            for (int a = 1; a < 4; ++a)
                if (r.k[static_cast<size_t>(a)] < 0 || r.k[static_cast<size_t>(a)] >= nc) throw InputError("compliant clip: wall face " + std::to_string(f) + " names a node outside the candidates");
            // Hard contact on the face's plane where the vertex lies over the face (over_face).
            OverFace of;
            const auto& h = had[static_cast<size_t>(v)];
            const bool was = h[0] == 2 + f || h[1] == 2 + f || (opt.wall_one_face && held && held->count({v, 2 + f}));
            if (!over_face(Xl.row(r.k[0]).transpose(), Xl.row(r.k[1]).transpose(), Xl.row(r.k[2]).transpose(), Xl.row(r.k[3]).transpose(), of,
                           was ? OVER_KEPT : OVER_FACE))
                continue;
            const Eigen::Vector3d& nh = of.nh;
            const double d = of.d, b0 = of.b0, b1 = of.b1, b2 = of.b2;
            wall_min = std::min(wall_min, d);
            // Within reach, and not far behind the face's plane where the frame started (a crease, the far side of a
            // fold). The plane's distance, as the row's gap: until session 35 the distance to the closed triangle, signed
            // only where the vertex projects inside it, so a vertex behind the plane but just beside an edge (within the
            // tenth above) counted as in front, and its row pushed it out through the wall in one frame (C0095's basilar
            // bifurcation: 45 wall rows pressing before the blades touched anything, grips of 57 kN at 18.5 deg).
            if (d >= opt.wall_reach_mm) continue;
            if (is_crease(*walls, r.k, plane_distance(Xs.row(r.k[0]).transpose(), Xs.row(r.k[1]).transpose(), Xs.row(r.k[2]).transpose(), Xs.row(r.k[3]).transpose()), opt))
                continue;
            Eigen::Matrix<double, 12, 1> g;
            g << nh, -b0 * nh, -b1 * nh, -b2 * nh;
            r.s = 2 + f;
            r.d = d;
            for (int a = 0; a < 4; ++a) {
                r.g[static_cast<size_t>(a)] = g.segment<3>(3 * a);
                r.d += r.g[static_cast<size_t>(a)].dot(Xf.row(r.k[static_cast<size_t>(a)]).transpose() - Xl.row(r.k[static_cast<size_t>(a)]).transpose());
            }
            rows.push_back(r);
            score.emplace_back(d, std::min({b0, b1, b2}));
            ++wall_rows;
        }
        if (opt.wall_one_face && rows.size() > wall_start) {
            std::vector<double> nearest(static_cast<size_t>(nc), std::numeric_limits<double>::infinity());  // per vertex: its smallest d
            for (size_t i = wall_start; i < rows.size(); ++i) {
                double& dn = nearest[static_cast<size_t>(rows[i].k[0])];
                dn = std::min(dn, score[i - wall_start].first);
            }
            std::vector<long long> best(static_cast<size_t>(nc), -1);  // per vertex: its row
            std::vector<char> stays(static_cast<size_t>(nc), 0);       // ... its face in `warm`
            auto in_warm = [&](size_t v, int sf) { return had[v][0] == sf || had[v][1] == sf; };
            for (size_t i = wall_start; i < rows.size(); ++i) {
                const size_t v = static_cast<size_t>(rows[i].k[0]);
                if (score[i - wall_start].first > nearest[v] + 0.02 || stays[v]) continue;
                if (in_warm(v, rows[i].s)) {
                    best[v] = static_cast<long long>(i);
                    stays[v] = 1;
                } else if (best[v] < 0 || score[i - wall_start].second > score[static_cast<size_t>(best[v]) - wall_start].second) {
                    best[v] = static_cast<long long>(i);
                }
            }
            // A second row: the vertex's face in `warm` that its best row is not, or one it lies behind (a pass took it
            // there, through a face its row was not on), where the two faces' planes differ by more than 10° (a
            // valley's two sides: one row alone lets the vertex through the other face; on nearly parallel faces the
            // second row would only make the LCP degenerate). The nearest such.
            constexpr double SECOND_COS = 0.9848;  // cos 10°
            std::vector<long long> second(static_cast<size_t>(nc), -1);
            for (size_t i = wall_start; i < rows.size(); ++i) {
                const size_t v = static_cast<size_t>(rows[i].k[0]);
                const long long b = best[v];
                if (b < 0 || b == static_cast<long long>(i) || !(in_warm(v, rows[i].s) || score[i - wall_start].first < 0)) continue;
                if (std::abs(rows[i].g[0].dot(rows[static_cast<size_t>(b)].g[0])) >= SECOND_COS) continue;
                if (second[v] < 0 || score[i - wall_start].first < score[static_cast<size_t>(second[v]) - wall_start].first) second[v] = static_cast<long long>(i);
            }
            // And every face that pressed the vertex in an earlier pass of this frame (`held`): one row each pass let
            // the passes cycle where a vertex lies over a corner of the opposite wall (the sample's held clip with the
            // faces from the heel, session 62: a vertex over a fan of faces took one pair of them in a pass, went
            // 0.021 mm through a third, took that one's neighbour in the next and came back out, in turn to the frame's
            // last pass, so every other frame ended 0.02 mm through). Kept, the passes' rows only grow within a frame.
            // As for the second row, only where its plane differs by more than 10° from each row the vertex keeps
            // (nearly parallel rows of one vertex make the LCP degenerate: the plates pressed together ended 1.4e-4 mm
            // off complementarity with them).
            std::vector<char> keep_held(rows.size(), 0);
            if (held && !held->empty()) {
                std::map<size_t, std::vector<size_t>> extra;  // per vertex with held rows: those kept so far
                for (size_t i = wall_start; i < rows.size(); ++i) {
                    const size_t v = static_cast<size_t>(rows[i].k[0]);
                    if (best[v] == static_cast<long long>(i) || second[v] == static_cast<long long>(i) || !held->count({rows[i].k[0], rows[i].s})) continue;
                    auto apart = [&](long long j) { return j < 0 || std::abs(rows[i].g[0].dot(rows[static_cast<size_t>(j)].g[0])) < SECOND_COS; };
                    std::vector<size_t>& ex = extra[v];
                    if (!apart(best[v]) || !apart(second[v]) || !std::all_of(ex.begin(), ex.end(), [&](size_t j) { return apart(static_cast<long long>(j)); })) continue;
                    keep_held[i] = 1;
                    ex.push_back(i);
                }
            }
            size_t w = wall_start;  // the kept rows moved down in place
            for (size_t i = wall_start; i < rows.size(); ++i)
                if (best[static_cast<size_t>(rows[i].k[0])] == static_cast<long long>(i) || second[static_cast<size_t>(rows[i].k[0])] == static_cast<long long>(i) ||
                    keep_held[i]) {
                    if (w != i) rows[w] = std::move(rows[i]);
                    ++w;
                }
            rows.resize(w);
            wall_rows = static_cast<int>(w - wall_start);
        }
    }
    const double t_rows = sw.seconds();
    const Eigen::Index m = static_cast<Eigen::Index>(rows.size()), mz = m + (free_theta ? 1 : 0);
    const double k = spring.k_nmm_per_rad, th0 = spring.preload_rad;
    // Per row its gap's rate on the first clip's θ (a further clip's rows do not move with it; friction rows: 0).
    std::vector<double> bth(rows.size(), 0.0);
    for (size_t i = 0; i < rows.size(); ++i) bth[i] = rows[i].clip == 0 ? rows[i].b : 0.0;
    // Delassus matrix and constant term: w = q + A z ≥ 0, z ≥ 0, zᵀ w = 0; z = (λ, μ_stop).
    Eigen::Map<Eigen::MatrixXd> A = scratch_square(delassus_scratch(), mz);
    Eigen::VectorXd q(mz);
    int pair_nodes = 0;
    {
        // Column by column: for each node b, with the rows j that touch it (gradient g_jb there), t = W_ab g_jb for
        // every node a, added to A_ij as g_iaᵀ t for the rows i that touch a, only where i ≥ j; then the upper triangle
        // mirrored. W's column of blocks b is read once, in rising a, and each column j of A is written where its rows
        // lie. (Until session 35 node pair by node pair, b ≤ a, writing A_ij and A_ji: every A_ji a write across the
        // matrix, a cache miss each; on the sample's held walls, 2,100 rows on 1,281 nodes, 270 ms a pass. Until session
        // 33 the blocks of the rows' candidates were first gathered into one contiguous matrix, and A made from
        // products with its columns; storing W's blocks in the Z order of the candidates' places did not help.)
        std::vector<int> local(static_cast<size_t>(nc), -1), nodes;
        for (const Row& r : rows)
            for (int a = 0; a < r.n; ++a)
                if (int& l = local[static_cast<size_t>(r.cand(a))]; l < 0) {
                    l = 0;
                    nodes.push_back(r.cand(a));
                }
        std::sort(nodes.begin(), nodes.end());
        const size_t p = nodes.size();
        pair_nodes = static_cast<int>(p);
        for (size_t a = 0; a < p; ++a) local[static_cast<size_t>(nodes[a])] = static_cast<int>(a);
        // Per node: the rows that touch it and their gradients there (compressed rows).
        std::vector<int> start(p + 1, 0);
        for (const Row& r : rows)
            for (int a = 0; a < r.n; ++a) ++start[static_cast<size_t>(local[static_cast<size_t>(r.cand(a))]) + 1];
        for (size_t a = 0; a < p; ++a) start[a + 1] += start[a];
        std::vector<int> row_of(static_cast<size_t>(start[p])), fill(start.begin(), start.end() - 1);
        Eigen::Matrix3Xd G(3, start[p]);
        for (Eigen::Index i = 0; i < m; ++i) {
            const Row& r = rows[static_cast<size_t>(i)];
            for (int a = 0; a < r.n; ++a) {
                const int e = fill[static_cast<size_t>(local[static_cast<size_t>(r.cand(a))])]++;
                row_of[static_cast<size_t>(e)] = static_cast<int>(i);
                G.col(e) = r.grad(a);
            }
        }
        // Per node its highest row: a node whose rows all lie above a column's first row adds nothing to it.
        std::vector<int> top(p, -1);
        for (size_t a = 0; a < p; ++a)
            for (int e = start[a]; e < start[a + 1]; ++e) top[a] = std::max(top[a], row_of[static_cast<size_t>(e)]);
        A.topLeftCorner(m, m).setZero();
        for (size_t b = 0; b < p; ++b) {
            const int b0 = start[b], nb = start[b + 1] - b0;
            int jmin = std::numeric_limits<int>::max();
            for (int jb = 0; jb < nb; ++jb) jmin = std::min(jmin, row_of[static_cast<size_t>(b0 + jb)]);
            for (size_t a = 0; a < p; ++a) {
                if (top[a] < jmin) continue;
                const int a0 = start[a], na = start[a + 1] - a0;
                const Eigen::Matrix3d Wab = Wblock(nodes[a], nodes[b]);
                for (int jb = 0; jb < nb; ++jb) {
                    const int j = row_of[static_cast<size_t>(b0 + jb)];
                    const Eigen::Vector3d t = Wab * G.col(b0 + jb);
                    double* Aj = &A(0, j);
                    for (int ia = 0; ia < na; ++ia) {
                        const int i = row_of[static_cast<size_t>(a0 + ia)];
                        if (i >= j) Aj[i] += G.col(a0 + ia).dot(t);
                    }
                }
            }
        }
        // The upper triangle from the lower, in tiles (a transposed copy column by column would read across A).
        constexpr Eigen::Index TILE = 64;
        for (Eigen::Index j0 = 0; j0 < m; j0 += TILE)
            for (Eigen::Index i0 = j0; i0 < m; i0 += TILE) {
                const Eigen::Index j1 = std::min(m, j0 + TILE), i1 = std::min(m, i0 + TILE);
                for (Eigen::Index i = i0; i < i1; ++i)
                    for (Eigen::Index j = j0; j < std::min(j1, i); ++j) A(j, i) = A(i, j);
            }
        if (free_theta)  // θ's own give, b bᵀ / k, column by column
            for (Eigen::Index j = 0; j < m; ++j) {
                const double bj = bth[static_cast<size_t>(j)] / k;
                for (Eigen::Index i = 0; i < m; ++i) A(i, j) += bth[static_cast<size_t>(i)] * bj;
            }
        for (Eigen::Index i = 0; i < m; ++i) {
            const Row& ri = rows[static_cast<size_t>(i)];
            q[i] = free_theta ? ri.d - bth[static_cast<size_t>(i)] * (th0 + theta_ref) : ri.d;
        }
    }
    const double t_delassus = sw.seconds();
    // A node that cannot move (held DOFs) has no compliance: its row binds θ only, and rows that differ only there
    // (the same place on both blades) would share their force in any proportion; so would a vertex pressed on two
    // faces of one edge of the opposite wall. A compliance of 10⁻⁹ of the largest on every row (constraint force
    // mixing) makes the forces unique at a gap error of 10⁻⁹ of a typical node's give per newton. (10⁻⁶ did not
    // make the pivoting on the sample's pressed walls converge any better, and cost the analytic tests 10⁻⁶.)
    constexpr double CFM = 1e-9;
    double amax = 0;
    for (Eigen::Index i = 0; i < m; ++i) amax = std::max(amax, A(i, i) - (free_theta ? bth[static_cast<size_t>(i)] * bth[static_cast<size_t>(i)] / k : 0.0));
    for (Eigen::Index i = 0; i < m; ++i) A(i, i) += CFM * amax + 1e-15;
    if (free_theta) {
        for (Eigen::Index i = 0; i < m; ++i) A(m, i) = A(i, m) = bth[static_cast<size_t>(i)] / k;
        A(m, m) = 1.0 / k;
        q[m] = -th0 - theta_lo;
    }
    // Warm start: the last frame's forces where the same candidate meets the same blade.
    Eigen::VectorXd z = Eigen::VectorXd::Zero(mz);
    if (warm) {
        std::map<std::pair<int, int>, double> last;
        for (size_t i = 0; i < warm->constraint.size() && i < warm->lambda.size(); ++i) last[warm->constraint[i]] = warm->lambda[i];
        for (Eigen::Index i = 0; i < m; ++i)
            if (auto it = last.find({rows[static_cast<size_t>(i)].k[0], rows[static_cast<size_t>(i)].s}); it != last.end()) z[i] = it->second;
    }
    CompliantFrame out;
    LcpOptions lo;
    lo.max_sweeps = opt.max_sweeps;
    lo.max_pivots = opt.max_pivots;
    lo.tolerance = opt.tolerance_mm;
    lo.accept = opt.accept_mm;
    Eigen::VectorXd zlo = Eigen::VectorXd::Zero(mz), zhi = Eigen::VectorXd::Constant(mz, std::numeric_limits<double>::infinity());
    for (Eigen::Index i = 0; i < m; ++i) {
        zlo[i] = rows[static_cast<size_t>(i)].lo;
        zhi[i] = rows[static_cast<size_t>(i)].hi;
    }
    const LcpResult lr = solve_box_lcp(A, q, zlo, zhi, z, lo);
    out.sweeps = lr.sweeps;
    out.pivots = lr.pivots;
    out.single_pivots = lr.single_pivots;
    out.refactors = lr.refactors;
    out.complementarity_mm = lr.violation;

    const double t_lcp = sw.seconds();
    // The frame's state: forces on the candidates, their displacement, θ, the blades' loads.
    out.candidate_forces = Eigen::VectorXd::Zero(3 * nc);
    for (Eigen::Index i = 0; i < m; ++i) {
        const Row& r = rows[static_cast<size_t>(i)];
        for (int a = 0; a < r.n; ++a) out.candidate_forces.segment<3>(3 * r.cand(a)) += z[i] * r.grad(a);
    }
    out.theta = theta_held ? *theta_held : theta_ref;
    if (free_theta) {
        double bl = 0;
        for (Eigen::Index i = 0; i < m; ++i) bl += bth[static_cast<size_t>(i)] * z[i];
        out.theta = std::max(theta_lo, (bl + z[m]) / k - th0);
    }
    // The candidates' displacement: the free state's plus the compliance's columns of the pressed candidates only.
    out.candidate_u = fu;
    {
        std::vector<char> done(static_cast<size_t>(nc), 0);
        std::vector<int> which;
        for (const Row& r : rows)
            for (int a = 0; a < r.n; ++a)
                if (!done[static_cast<size_t>(r.cand(a))]++) which.push_back(r.cand(a));
        add_compliance_times(lin, out.candidate_forces, which, out.candidate_u);
    }
    out.loads.opening_rad = out.theta;
    out.loads.spring_torque_nmm = spring.torque(out.theta);
    out.more_loads.resize(ncl - 1);
    for (size_t c = 1; c < ncl; ++c) {
        out.more_loads[c - 1].opening_rad = clip_at[c].theta;
        out.more_loads[c - 1].spring_torque_nmm = (*more)[c - 1].spring.torque(clip_at[c].theta);
    }
    for (Eigen::Index i = 0; i < m; ++i) {
        const Row& r = rows[static_cast<size_t>(i)];
        out.lambda.push_back(z[i]);
        out.constraint.emplace_back(r.k[0], r.s);
        const CompliantRowKind kind = compliant_row_kind(r.s);
        BladeLoads& L = kind.wall || r.clip == 0 ? out.loads : out.more_loads[static_cast<size_t>(r.clip - 1)];
        if (kind.friction) {  // a friction row (its force may have either sign)
            const int side = kind.side;
            L.friction_n[side] += std::abs(z[i]);
            if (r.hi > 0 && std::abs(z[i]) >= r.hi * (1 - 1e-9)) ++L.sliding[side];
            for (int a = 0; a < r.n; ++a) L.net_force -= z[i] * r.grad(a);
            continue;
        }
        if (z[i] <= 0) continue;
        if (kind.wall) {
            ++out.wall_contacts;
            out.wall_force_n += z[i];
            continue;
        }
        const int side = kind.side;
        L.force_n[side] += z[i];
        L.moment_nmm[side] += 2 * r.b * z[i];
        ++L.contacts[side];
        L.net_force -= z[i] * r.g[0];
    }
    out.wall_rows = wall_rows;
    out.wall_min_distance_mm = wall_min;
    out.pair_nodes = pair_nodes;
    out.seconds = sw.seconds();
    out.rows_s = t_rows;
    out.delassus_s = t_delassus - t_rows;
    out.lcp_s = t_lcp - t_delassus;
    return out;
}

/// The smallest distance from its face's plane of a wall pair's vertex that lies over its face (over_face), the
/// candidates displaced by u (inf: none).
/// Pairs whose vertex lay further than opt.wall_behind_mm behind its face's plane where the frame started (`start`: a
/// crease, the far side of a fold; solve_pass makes them no constraint) are left out.
/// With `deepened`: the same closest distance, a pair that started further than beyond_mm behind its face's plane
/// measured from there (compliant_walls_at).
double wall_min_distance(const Linearisation& lin, const CompliantWalls& walls, const Eigen::VectorXd& u, const Eigen::VectorXd& start,
                         const CompliantOptions& opt, std::array<int, 2>* worst = nullptr, double* deepened = nullptr,
                         double beyond_mm = std::numeric_limits<double>::infinity()) {
    const Eigen::MatrixX3d& Xf = lin.free_positions();
    const Eigen::VectorXd& fu = lin.free_candidate_u();
    auto at = [&](int k) { return Eigen::Vector3d(Xf.row(k).transpose() + u.segment<3>(3 * k) - fu.segment<3>(3 * k)); };
    auto at_start = [&](int k) { return Eigen::Vector3d(Xf.row(k).transpose() + start.segment<3>(3 * k) - fu.segment<3>(3 * k)); };
    double out = std::numeric_limits<double>::infinity();
    if (deepened) *deepened = out;
    for (const auto& [v, f] : walls.pairs) {
        const double d0 = plane_distance(at_start(v), at_start(walls.faces(f, 0)), at_start(walls.faces(f, 1)), at_start(walls.faces(f, 2)));
        if (is_crease(walls, {v, walls.faces(f, 0), walls.faces(f, 1), walls.faces(f, 2)}, d0, opt)) continue;
        OverFace of;
        if (!over_face(at(v), at(walls.faces(f, 0)), at(walls.faces(f, 1)), at(walls.faces(f, 2)), of)) continue;
        if (of.d < out) {
            out = of.d;
            if (worst) *worst = {v, f};
        }
        if (deepened) *deepened = std::min(*deepened, d0 < -beyond_mm ? of.d - d0 : of.d);
    }
    return out;
}

/// A wall vertex behind a face by more than this counts as through it (a pressed vertex's linearisation error, well
/// under the 0.02 mm limit, does not), down to the search's crossing depth (0.25 mm unless it says).
constexpr double CONTACT_ROUNDOFF_MM = 1e-3;
double crossing_depth(const ContactParams& cp) { return cp.depth_mm > 0 ? cp.depth_mm : 0.25; }

/// ANEU_WALL_TRACE (stderr), at a frame's end `f`: how much of the walls' force the rows kept beyond their face's edge
/// carry (OVER_KEPT: the face's plane holds a vertex beyond its edge, over a ridge as far out as the plane or further)
/// and how far those vertices stand from the nearest face they lie over by the ordinary rule (a gap the kept row may
/// hold open); and where the walls end more than 0.02 mm through each other, the worst pair's history: where it stood
/// at the start and after each pass (`pass_ends`), and which rows its vertex had.
void trace_walls(const Linearisation& lin, const CompliantWalls& walls, const CompliantFrame& f, const Eigen::VectorXd& start, const std::array<int, 2>& worst,
                 const std::vector<CompliantFrame>& pass_ends) {
    const Eigen::MatrixX3d& Xf = lin.free_positions();
    const Eigen::VectorXd& fu = lin.free_candidate_u();
    auto at = [&](const Eigen::VectorXd& u, int k) { return Eigen::Vector3d(Xf.row(k).transpose() + u.segment<3>(3 * k) - fu.segment<3>(3 * k)); };
    auto over = [&](const Eigen::VectorXd& u, int v, int fc, OverFace& of) {
        return over_face(at(u, v), at(u, walls.faces(fc, 0)), at(u, walls.faces(fc, 1)), at(u, walls.faces(fc, 2)), of);
    };
    if (f.wall_contacts > 0) {
        int n_beyond = 0;
        double force = 0, beyond = 0, gap = 0;
        for (size_t i = 0; i < f.constraint.size() && i < f.lambda.size(); ++i) {
            const auto [v, sf] = f.constraint[i];
            if (sf < 2 || !(f.lambda[i] > 0)) continue;
            force += f.lambda[i];
            OverFace of;
            if (over(f.candidate_u, v, sf - 2, of)) continue;
            ++n_beyond;
            beyond += f.lambda[i];
            double nearest = std::numeric_limits<double>::infinity();
            for (const auto& [pv, pf] : walls.pairs)
                if (pv == v && over(f.candidate_u, v, pf, of)) nearest = std::min(nearest, of.d);
            if (std::isfinite(nearest)) gap = std::max(gap, nearest);
        }
        std::fprintf(stderr, "wall rows beyond their face's edge: %d pressed, %.4f of %.4f N, the largest gap to a face they lie over %.4f mm\n", n_beyond, beyond, force, gap);
    }
    if (!(f.wall_min_distance_mm < -0.02) || worst[0] < 0) return;
    const int v = worst[0], fc = worst[1];
    auto state = [&](const Eigen::VectorXd& u) {
        OverFace of;
        const bool is_over = over(u, v, fc, of);
        char buf[160];
        std::snprintf(buf, sizeof buf, "d %+.4f b (%.2f %.2f %.2f)%s", of.d, of.b0, of.b1, of.b2, is_over ? "" : " not over");
        return std::string(buf);
    };
    std::fprintf(stderr, "wall worst: vertex %d face %d (%d %d %d): start %s\n", v, fc, walls.faces(fc, 0), walls.faces(fc, 1), walls.faces(fc, 2), state(start).c_str());
    for (size_t p = 0; p < pass_ends.size(); ++p) {
        std::string rows_of_v;
        for (size_t i = 0; i < pass_ends[p].constraint.size(); ++i)
            if (pass_ends[p].constraint[i].first == v && pass_ends[p].constraint[i].second >= 2)
                rows_of_v += " " + std::to_string(pass_ends[p].constraint[i].second - 2) + ":" + std::to_string(i < pass_ends[p].lambda.size() ? pass_ends[p].lambda[i] : 0.0);
        const Eigen::VectorXd& from = p == 0 ? start : pass_ends[p - 1].candidate_u;
        const double moved = (pass_ends[p].candidate_u - from).lpNorm<Eigen::Infinity>();
        const double vmoved = (pass_ends[p].candidate_u.segment<3>(3 * v) - from.segment<3>(3 * v)).norm();
        std::fprintf(stderr, "wall worst: pass %zu end %s; moved %.4f mm (its vertex %.4f); its wall rows (face:force)%s\n", p + 1, state(pass_ends[p].candidate_u).c_str(),
                     moved, vmoved, rows_of_v.empty() ? " none" : rows_of_v.c_str());
        // Every face the vertex is paired with that it lies over to OVER_KEPT there: the choice the next pass's rows make.
        std::string faces_of_v;
        for (const auto& [pv, pf] : walls.pairs) {
            OverFace of;
            if (pv != v || !over_face(at(pass_ends[p].candidate_u, v), at(pass_ends[p].candidate_u, walls.faces(pf, 0)), at(pass_ends[p].candidate_u, walls.faces(pf, 1)),
                                      at(pass_ends[p].candidate_u, walls.faces(pf, 2)), of, -0.5))
                continue;
            char buf[96];
            std::snprintf(buf, sizeof buf, " %d:d%+.4f,b%.2f", pf, of.d, std::min({of.b0, of.b1, of.b2}));
            faces_of_v += buf;
        }
        std::fprintf(stderr, "wall worst: pass %zu end: the faces it lies over (face:d,smallest b)%s\n", p + 1, faces_of_v.empty() ? " none" : faces_of_v.c_str());
    }
}

}  // namespace

CompliantFrame solve_compliant_clip(const Linearisation& lin, const ClipBlades& blades, const ClipSpring& spring,
                                    std::optional<double> theta_held, double theta_start, const CompliantFrame* warm,
                                    const CompliantOptions& opt, const CompliantWalls* walls, const Eigen::VectorXd* start_u,
                                    const std::vector<CompliantClip>* more) {
    const Stopwatch sw;
    const Eigen::Index nc = static_cast<Eigen::Index>(lin.candidates().size());
    if (start_u && start_u->size() != 3 * nc)
        throw InputError("compliant clip: a start of " + std::to_string(start_u->size()) + " values for " + std::to_string(nc) + " candidates");
    const Eigen::VectorXd start = start_u ? *start_u : warm && warm->candidate_u.size() == 3 * nc ? warm->candidate_u : lin.free_candidate_u();
    // The gaps are linear in the candidates' motion only to first order (a blade's or a face's normal turns as it
    // moves): passes re-linearise them where the last pass ended, on the same compliance, until the candidates
    // move less than the sweeps' tolerance.
    //
    // On a borrowed W (another state's: Linearisation::borrowed) a pass's end free + W f is this tangent's only
    // approximately: each pass's end is made exact (its forces' displacement by one back substitution), and the next
    // pass starts from the free state that puts that exact end at those forces on W (free' = exact − W f), so that its
    // rows are linearised where the candidates really are and W predicts only the change (an approximate Jacobian:
    // the passes converge to the exact frame while W is near this tangent's inverse). They go on until a pass's
    // predicted end is within opt.borrow_tolerance_mm of its exact one.
    const bool borrowed = lin.borrowed();
    Eigen::VectorXd free_eff;
    double mismatch = 0;
    // The wall rows (vertex, 2 + face) that pressed in a pass of this frame so far: kept in its later passes with
    // opt.wall_one_face (solve_pass; the rows of all faces a vertex lies over need no such memory).
    std::set<std::pair<int, int>> held;
    auto pass = [&](const CompliantFrame* from) {
        const Eigen::VectorXd* fu = borrowed && free_eff.size() == 3 * nc ? &free_eff : nullptr;
        CompliantFrame g = solve_pass(lin, blades, spring, theta_held, theta_start, from, opt, walls, start, more, fu, &held);
        for (size_t i = 0; i < g.constraint.size() && i < g.lambda.size(); ++i)
            if (g.constraint[i].second >= 2 && g.lambda[i] > 0) held.insert(g.constraint[i]);
        if (borrowed) {
            const Stopwatch bw;
            const Eigen::VectorXd exact = lin.candidate_displacement(g.candidate_forces);
            const Eigen::VectorXd& used = fu ? *fu : lin.free_candidate_u();
            mismatch = (exact - g.candidate_u).lpNorm<Eigen::Infinity>();
            free_eff = exact - (g.candidate_u - used);
            g.candidate_u = exact;
            g.compliance_mismatch_mm = mismatch;
            g.lcp_s += bw.seconds();
        }
        return g;
    };
    // The first pass too predicts only the change from the last frame's forces: the free state that puts their exact
    // displacement on this tangent at them on W (from the tangent's own free state, W predicts the whole rebound of
    // the gripped tissue, and on the tube 3 frames' old W was 0.1-0.17 mm off there: the passes' rows came and went,
    // and the frames diverged as the tube flattened).
    if (borrowed && warm && warm->candidate_forces.size() == 3 * nc && !warm->candidate_forces.isZero(0.0)) {
        const Eigen::VectorXd& fw = warm->candidate_forces;
        std::vector<int> all(static_cast<size_t>(nc));
        std::iota(all.begin(), all.end(), 0);
        Eigen::VectorXd Wf = Eigen::VectorXd::Zero(3 * nc);
        add_compliance_times(lin, fw, all, Wf);
        free_eff = lin.candidate_displacement(fw) - Wf;
    }
    const int max_passes = borrowed ? std::max(opt.geometry_passes, opt.borrow_passes) : opt.geometry_passes;
    CompliantFrame f = pass(warm);
    static const bool wall_trace = std::getenv("ANEU_WALL_TRACE") != nullptr;
    std::vector<CompliantFrame> pass_ends;  // ANEU_WALL_TRACE: each pass's end, for the worst crossing's history
    if (wall_trace && walls) pass_ends.push_back(f);
    int passes = 1, growing = 0;
    for (; passes < max_passes; ++passes) {
        if (borrowed && passes >= opt.geometry_passes && mismatch <= opt.borrow_tolerance_mm) break;
        // Passes whose mismatch has grown twice in a row diverge (W too far from this tangent: C0001's tandem had one
        // end 1.69 mm off after 16): the frame stops there, reporting it.
        if (borrowed && growing >= 2) break;
        const double mismatch_before = mismatch;
        CompliantFrame g = pass(&f);
        growing = borrowed && mismatch > opt.borrow_tolerance_mm && mismatch > mismatch_before ? growing + 1 : 0;
        if (wall_trace && walls) pass_ends.push_back(g);
        g.rows_s += f.rows_s;
        g.delassus_s += f.delassus_s;
        g.lcp_s += f.lcp_s;
        const double moved = (g.candidate_u - f.candidate_u).lpNorm<Eigen::Infinity>();
        static const bool trace = std::getenv("ANEU_PASS_TRACE") != nullptr;
        if (trace) {  // how the passes settle (or do not): compliance.md, session 32
            Eigen::Index worst = 0;
            (g.candidate_u - f.candidate_u).cwiseAbs().maxCoeff(&worst);
            const Eigen::Vector3d dw = (g.candidate_u - f.candidate_u).segment<3>(3 * (worst / 3));
            Eigen::Vector3d t, n, w;
            blades.frame(1, g.theta, t, n, w);
            std::fprintf(stderr, "pass %d: moved %.3e mm (candidate %ld: %.3e along the blades, %.3e across their width, %.3e along blade +1's normal), rows %zu, grip %.5f N\n",
                         passes + 1, moved, static_cast<long>(worst / 3), dw.dot(t), dw.dot(w), dw.dot(n), g.lambda.size(), 0.5 * (g.loads.force_n[0] + g.loads.force_n[1]));
        }
        f = std::move(g);
        if (moved <= 1e3 * opt.tolerance_mm && (!borrowed || mismatch <= opt.borrow_tolerance_mm)) {
            ++passes;
            break;
        }
    }
    // Where the frame ends, on the pairs it constrains (the passes measured it where each started, creases included:
    // the sample's held walls read −0.122 mm there, while its lumen at the end has them 0.002 mm through each other on
    // the neck line and 0.021 mm at most anywhere, session 35).
    std::array<int, 2> worst{-1, -1};
    if (walls) f.wall_min_distance_mm = wall_min_distance(lin, *walls, f.candidate_u, start, opt, &worst);
    // A frame whose walls end through each other by more than opt.wall_crossed_mm (a pass that moved a vertex over a
    // face its rows left out) takes more passes, from there, while they do: the next has that face's row.
    if (walls)
        for (int extra = 0; extra < opt.wall_extra_passes && f.wall_min_distance_mm < -opt.wall_crossed_mm; ++extra) {
            CompliantFrame g = pass(&f);
            g.rows_s += f.rows_s;
            g.delassus_s += f.delassus_s;
            g.lcp_s += f.lcp_s;
            if (wall_trace) pass_ends.push_back(g);
            f = std::move(g);
            ++passes;
            f.wall_min_distance_mm = wall_min_distance(lin, *walls, f.candidate_u, start, opt, &worst);
        }
    f.passes = passes;
    if (wall_trace && walls) trace_walls(lin, *walls, f, start, worst, pass_ends);
    f.seconds = sw.seconds();
    return f;
}

}  // namespace aneu::fem

namespace aneu::fem {

void carry_compliant_frames(const std::vector<int>& from_cand, const Eigen::MatrixX3i& from_faces, const std::vector<int>& to_cand,
                            const Eigen::MatrixX3i& to_faces, const Eigen::VectorXd& u, CompliantFrame& last, CompliantWallSearch& ws) {
    const auto nf = static_cast<Eigen::Index>(from_cand.size()), nt = static_cast<Eigen::Index>(to_cand.size());
    std::map<int, int> slot;  // body node -> its index in to_cand
    for (Eigen::Index k = 0; k < nt; ++k) {
        const int a = to_cand[static_cast<size_t>(k)];
        if (a < 0 || 3 * static_cast<Eigen::Index>(a) + 2 >= u.size())
            throw InputError("carry compliant frames: node " + std::to_string(a) + " outside the body's displacement of " + std::to_string(u.size()) + " DOFs");
        slot.emplace(a, static_cast<int>(k));
    }
    std::vector<int> to(static_cast<size_t>(nf), -1);  // old candidate -> new one
    for (Eigen::Index k = 0; k < nf; ++k)
        if (auto it = slot.find(from_cand[static_cast<size_t>(k)]); it != slot.end()) to[static_cast<size_t>(k)] = it->second;
    auto key = [](const std::vector<int>& cand, const Eigen::MatrixX3i& faces, Eigen::Index f) {
        std::array<int, 3> k{};
        for (int c = 0; c < 3; ++c) {
            const int i = faces(f, c);
            if (i < 0 || static_cast<size_t>(i) >= cand.size())
                throw InputError("carry compliant frames: face " + std::to_string(f) + " names candidate " + std::to_string(i) + " of " + std::to_string(cand.size()));
            k[static_cast<size_t>(c)] = cand[static_cast<size_t>(i)];
        }
        std::sort(k.begin(), k.end());
        return k;
    };
    std::map<std::array<int, 3>, int> face_slot;
    for (Eigen::Index f = 0; f < to_faces.rows(); ++f) face_slot.emplace(key(to_cand, to_faces, f), static_cast<int>(f));
    std::vector<int> face_to(static_cast<size_t>(from_faces.rows()), -1);
    for (Eigen::Index f = 0; f < from_faces.rows(); ++f)
        if (auto it = face_slot.find(key(from_cand, from_faces, f)); it != face_slot.end()) face_to[static_cast<size_t>(f)] = it->second;

    std::vector<std::pair<int, int>> constraint;
    std::vector<double> lambda;
    for (size_t i = 0; i < last.constraint.size(); ++i) {
        auto [c, s] = last.constraint[i];
        const int k = c >= 0 && c < nf ? to[static_cast<size_t>(c)] : -1;
        if (k < 0) continue;
        if (s >= 2) {  // a wall pair: (vertex, 2 + face)
            const int f = s - 2 < from_faces.rows() ? face_to[static_cast<size_t>(s - 2)] : -1;
            if (f < 0) continue;
            s = 2 + f;
        }
        constraint.emplace_back(k, s);
        lambda.push_back(i < last.lambda.size() ? last.lambda[i] : 0.0);
    }
    last.constraint = std::move(constraint);
    last.lambda = std::move(lambda);
    const bool have_u = last.candidate_u.size() == 3 * nf, have_f = last.candidate_forces.size() == 3 * nf;
    Eigen::VectorXd cu(3 * nt), cf = Eigen::VectorXd::Zero(3 * nt);
    for (Eigen::Index k = 0; k < nt; ++k) cu.segment<3>(3 * k) = u.segment<3>(3 * static_cast<Eigen::Index>(to_cand[static_cast<size_t>(k)]));
    for (Eigen::Index k = 0; k < nf; ++k) {
        const int j = to[static_cast<size_t>(k)];
        if (j < 0) continue;
        if (have_u) cu.segment<3>(3 * j) = last.candidate_u.segment<3>(3 * k);
        if (have_f) cf.segment<3>(3 * j) = last.candidate_forces.segment<3>(3 * k);
    }
    last.candidate_u = std::move(cu);
    last.candidate_forces = std::move(cf);

    std::vector<int> close;
    for (int v : ws.params.close_vertices)
        if (v >= 0 && v < nf && to[static_cast<size_t>(v)] >= 0) close.push_back(to[static_cast<size_t>(v)]);
    std::sort(close.begin(), close.end());
    ws.params.close_vertices = std::move(close);
    ws.pairs.clear();
    ws.searched_at.resize(0);
    ws.ended_at.resize(0);
    ws.ended_behind.clear();
    ws.ended_deepest = 0;
}

CompliantFrame solve_compliant_clip_walls(const Linearisation& lin, const Eigen::MatrixX3d& Xc, const Eigen::MatrixX3i& faces, CompliantWallSearch& ws,
                                          const ClipBlades& blades, const ClipSpring& spring, std::optional<double> theta_held, double theta_start,
                                          const CompliantFrame* warm, const CompliantOptions& opt, int* repeats, const Eigen::VectorXd* start,
                                          const std::vector<CompliantClip>* more) {
    const Eigen::Index nc = static_cast<Eigen::Index>(lin.candidates().size());
    if (Xc.rows() != nc) throw InputError("compliant clip: " + std::to_string(Xc.rows()) + " candidate positions for " + std::to_string(nc) + " candidates");
    if (start && start->size() != 3 * nc)
        throw InputError("compliant clip: a start of " + std::to_string(start->size()) + " values for " + std::to_string(nc) + " candidates");
    ContactParams& cp = ws.params;
    const Eigen::VectorXd u0 = start ? *start : warm && warm->candidate_u.size() == 3 * nc ? warm->candidate_u : lin.free_candidate_u();
    const double depth = crossing_depth(cp);
    // (Hard contact leaves a pressed vertex on its face's plane, to the gaps' linearisation: a micrometre behind it is
    // not a crossing, CONTACT_ROUNDOFF_MM; the next frame's row pushes it back.)
    // The (vertex, face) pairs behind each other at u, sorted, and the deepest of them.
    struct Behind {
        std::vector<std::pair<int, int>> pairs;
        double deepest = 0;
    };
    auto crossings = [&](const Eigen::VectorXd& u) {
        Behind c;
        for (const SurfaceCrossing& q : surface_crossings(Xc, faces, u, cp.exclude_rings, depth, nullptr, &cp.face_surface))
            if (q.depth_mm > CONTACT_ROUNDOFF_MM) {
                c.pairs.emplace_back(q.v, q.f);
                c.deepest = std::max(c.deepest, q.depth_mm);
            }
        std::sort(c.pairs.begin(), c.pairs.end());
        return c;
    };
    Stopwatch sw;
    // What is behind a face where the frame starts stays out of the count (a crease, an earlier crossing): the last
    // frame's end, when it ended here.
    const Behind before = ws.ended_at.size() == u0.size() && ws.ended_at == u0 ? Behind{ws.ended_behind, ws.ended_deepest} : crossings(u0);
    CompliantWalls walls;
    walls.faces = faces;
    walls.rest = Xc;
    if (repeats) *repeats = 0;
    double search_s = sw.lap(), frames_s = 0;
    CompliantFrame acc;
    bool grew = false;  // close vertices added: search again
    for (int round = 0;; ++round) {
        // The pairs: searched again when the candidates have moved far enough since the last search that a pair
        // beyond its reach then could be within the rows' reach now.
        const double slack = 0.5 * (cp.search_mm - opt.wall_reach_mm);
        if (grew || ws.searched_at.size() != u0.size() || slack <= 0 || (u0 - ws.searched_at).lpNorm<Eigen::Infinity>() > slack) {
            ws.pairs = contact_pairs(Xc, faces, u0, cp, std::max(opt.wall_behind_mm, opt.wall_through_mm));
            ws.searched_at = u0;
            ++ws.searches;
        }
        walls.pairs = ws.pairs;
        search_s += sw.lap();
        CompliantFrame f = solve_compliant_clip(lin, blades, spring, theta_held, theta_start, warm, opt, &walls, &u0, more);
        frames_s += sw.lap();
        acc.rows_s += f.rows_s;
        acc.delassus_s += f.delassus_s;
        acc.lcp_s += f.lcp_s;
        // Nothing moved (the blades closing through the air, no force on any candidate): what is behind a face is
        // what was (the sample's air frames: 8.7 of their 9.4 ms were this check).
        const Behind end = f.candidate_u == u0 ? before : crossings(f.candidate_u);
        f.wall_crossed_mm = end.deepest;
        std::vector<std::pair<int, int>> left;
        std::set_difference(end.pairs.begin(), end.pairs.end(), before.pairs.begin(), before.pairs.end(), std::back_inserter(left));
        f.wall_crossings = static_cast<int>(left.size());
        search_s += sw.lap();
        f.rows_s = acc.rows_s;
        f.delassus_s = acc.delassus_s;
        f.lcp_s = acc.lcp_s;
        f.search_s = search_s;
        f.seconds = search_s + frames_s;
        // Solved again only where pairing the crossings closely changes the frame's problem (crossings_need_pairs:
        // the sample's held clip solved every other frame 4 times, the last 3 alike, a vertex ending 0.12 mm behind
        // a face it was closely paired with, its row left out as it started behind the face's plane).
        if (round == 3 || !crossings_need_pairs(left, ws.pairs, cp.close_vertices)) {
            ws.ended_at = f.candidate_u;
            ws.ended_behind = end.pairs;
            ws.ended_deepest = end.deepest;
            return f;
        }
        if (repeats) ++*repeats;
        // The crossing vertices and their rings paired with every face near their path, in the frame solved again
        // and in the frames after.
        pair_crossings_closely(cp, faces, u0, f.candidate_u, left);
        grew = true;
    }
}

CompliantWallsAt compliant_walls_at(const Linearisation& lin, const Eigen::MatrixX3d& Xc, const Eigen::MatrixX3i& faces, const CompliantWallSearch& ws,
                                    const Eigen::VectorXd& u, const Eigen::VectorXd& start, const CompliantOptions& opt, double beyond_mm) {
    const Eigen::Index nc = static_cast<Eigen::Index>(lin.candidates().size());
    if (Xc.rows() != nc || u.size() != 3 * nc || start.size() != 3 * nc)
        throw InputError("compliant walls: positions, displacement or start that do not fit the " + std::to_string(nc) + " candidates");
    CompliantWallsAt out;
    CompliantWalls walls;
    walls.faces = faces;
    walls.rest = Xc;
    walls.pairs = ws.pairs;
    out.min_distance_mm = wall_min_distance(lin, walls, u, start, opt, nullptr, &out.deepened_mm, beyond_mm);
    const ContactParams& cp = ws.params;
    const double depth = crossing_depth(cp);
    // A crossing already deeper than beyond_mm at the start: how much deeper it went. (Looked for at the start down to
    // twice the crossings' depth: a vertex just beyond it there, which the step brings back within it, is one the step
    // took out, not in. The sample's 2 mm jaws at t = 1.256 s: not found at the start, 0.2493 mm at 1/64 of the step,
    // 0.2163 at half of it, read as a new crossing each time.)
    std::map<std::pair<int, int>, double> started;
    if (std::isfinite(beyond_mm))
        for (const SurfaceCrossing& q : surface_crossings(Xc, faces, start, cp.exclude_rings, 2 * depth, nullptr, &cp.face_surface))
            if (q.depth_mm > beyond_mm) started[{q.v, q.f}] = q.depth_mm;
    for (const SurfaceCrossing& q : surface_crossings(Xc, faces, u, cp.exclude_rings, depth, nullptr, &cp.face_surface)) {
        if (!(q.depth_mm > CONTACT_ROUNDOFF_MM)) continue;
        out.crossed_mm = std::max(out.crossed_mm, q.depth_mm);
        const auto it = started.find({q.v, q.f});
        out.deepened_crossed_mm = std::max(out.deepened_crossed_mm, it == started.end() ? q.depth_mm : q.depth_mm - it->second);
    }
    return out;
}

}  // namespace aneu::fem
