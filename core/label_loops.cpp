// SPDX-License-Identifier: MIT
// Loops of edges on a triangle surface: chained edges, and the border of a labelled region (the neck line).
#include "aneu/core/label_loops.hpp"

#include <algorithm>
#include <map>
#include <unordered_map>

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

}  // namespace aneu
