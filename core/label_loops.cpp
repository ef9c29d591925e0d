// SPDX-License-Identifier: MIT
// Loops of edges on a triangle surface: chained edges, and the border of a labelled region (the neck line).
#include "aneu/core/label_loops.hpp"

#include <algorithm>
#include <map>
#include <numeric>
#include <unordered_map>

#include <Eigen/Geometry>

namespace aneu {

std::vector<std::vector<int>> chain_loops(const std::vector<std::array<int, 2>>& edges) {
    std::unordered_map<int, std::vector<int>> nb;
    for (const auto& e : edges) {
        nb[e[0]].push_back(e[1]);
        nb[e[1]].push_back(e[0]);
    }
    std::vector<int> starts;
    for (const auto& [v, l] : nb) starts.push_back(v);
    std::sort(starts.begin(), starts.end());  // deterministic
    std::unordered_map<int, char> used;
    std::vector<std::vector<int>> loops;
    for (int s : starts) {
        if (used[s]) continue;
        std::vector<int> loop{s};
        used[s] = 1;
        int prev = -1, cur = s;
        for (;;) {
            int next = -1;
            for (int w : nb[cur])
                if (w != prev && !used[w]) {
                    next = w;
                    break;
                }
            if (next < 0) break;
            used[next] = 1;
            loop.push_back(next);
            prev = cur;
            cur = next;
        }
        if (loop.size() >= 3) loops.push_back(std::move(loop));
    }
    return loops;
}

std::vector<std::vector<int>> label_border_loops(const Eigen::MatrixX3i& F, const Eigen::VectorXi& labels, int label) {
    std::map<std::pair<int, int>, std::array<int, 2>> edge_faces;  // (min,max) -> (#faces with the label, #others)
    for (Eigen::Index f = 0; f < F.rows(); ++f)
        for (int k = 0; k < 3; ++k) {
            auto& c = edge_faces[std::minmax(F(f, k), F(f, (k + 1) % 3))];
            ++c[labels[f] == label ? 0 : 1];
        }
    std::vector<std::array<int, 2>> border;
    for (const auto& [e, c] : edge_faces)
        if (c[0] == 1 && c[1] == 1) border.push_back({e.first, e.second});
    return chain_loops(border);
}

std::vector<std::vector<int>> neck_border_loops(const Eigen::MatrixX3i& F, const Eigen::MatrixX3d& V, const Eigen::VectorXi& labels, int label) {
    std::vector<std::vector<int>> loops = label_border_loops(F, labels, label);
    if (loops.size() <= 1) return loops;
    // Pieces of one side: union of faces across shared edges with both faces on the same side.
    const auto nf = static_cast<size_t>(F.rows());
    std::vector<int> parent(nf);
    std::iota(parent.begin(), parent.end(), 0);
    auto find = [&](int a) {
        while (parent[static_cast<size_t>(a)] != a) a = parent[static_cast<size_t>(a)] = parent[static_cast<size_t>(parent[static_cast<size_t>(a)])];
        return a;
    };
    std::map<std::pair<int, int>, std::vector<int>> edge_faces;
    for (Eigen::Index f = 0; f < F.rows(); ++f)
        for (int k = 0; k < 3; ++k) edge_faces[std::minmax(F(f, k), F(f, (k + 1) % 3))].push_back(static_cast<int>(f));
    auto side = [&](int f) { return labels[f] == label; };
    for (const auto& [e, fs] : edge_faces)
        for (size_t i = 1; i < fs.size(); ++i)
            if (side(fs[0]) == side(fs[i])) parent[static_cast<size_t>(find(fs[0]))] = find(fs[i]);
    std::vector<double> area(nf, 0.0);
    std::vector<char> open(nf, 0);
    for (Eigen::Index f = 0; f < F.rows(); ++f) {
        const Eigen::Vector3d a = V.row(F(f, 0)), b = V.row(F(f, 1)), c = V.row(F(f, 2));
        area[static_cast<size_t>(find(static_cast<int>(f)))] += 0.5 * (b - a).cross(c - a).norm();
    }
    for (const auto& [e, fs] : edge_faces)
        if (fs.size() == 1) open[static_cast<size_t>(find(fs[0]))] = 1;
    int big_in = -1, big_out = -1;
    for (Eigen::Index f = 0; f < F.rows(); ++f) {
        const int r = find(static_cast<int>(f));
        int& big = side(static_cast<int>(f)) ? big_in : big_out;
        if (big < 0 || area[static_cast<size_t>(r)] > area[static_cast<size_t>(big)]) big = r;
    }
    bool any_open = false;
    for (Eigen::Index f = 0; f < F.rows(); ++f)
        if (!side(static_cast<int>(f)) && open[static_cast<size_t>(find(static_cast<int>(f)))]) any_open = true;
    std::vector<std::vector<int>> kept;
    for (auto& loop : loops) {
        // The pieces on either side of the loop's first edge.
        const auto it = edge_faces.find(std::minmax(loop[0], loop[1]));
        if (it == edge_faces.end() || it->second.size() != 2) continue;
        int in = it->second[0], out = it->second[1];
        if (!side(in)) std::swap(in, out);
        const int pin = find(in), pout = find(out);
        if (pin == big_in && (any_open ? open[static_cast<size_t>(pout)] != 0 : pout == big_out)) kept.push_back(std::move(loop));
    }
    return kept.empty() ? label_border_loops(F, labels, label) : kept;
}

}  // namespace aneu
