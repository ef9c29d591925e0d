// SPDX-License-Identifier: MIT
// A patch's tissue overlapping itself, measured again from aneusim's ANEU_PATCH_DUMP file with this build's
// fem::nodes_inside_elements (the report's patch_nodes_in_other_tissue and patch_tissue_overlap_mm: nodes off the
// interface lying more than 1 µm inside an element not their own), so that a dump from an earlier build is measured by
// today's rule without running the scene again.
//
//     aneu_bench_overlap DUMP [--list N]
//
// Prints per patch the nodes deeper than 1 µm and the deepest, then the N deepest (node, depth, element, blade
// candidate). bench/patch_tissue_overlap.py reads the same dump for where they lie.
#include <Eigen/Core>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "aneu/fem/contact.hpp"

namespace {

struct Patch {
    std::vector<Eigen::Vector3d> x;
    std::vector<int> iface, cand;
    std::vector<std::vector<int>> elements;
};

}  // namespace

int main(int argc, char** argv) {
    if (argc < 2) {
        std::fprintf(stderr, "usage: aneu_bench_overlap DUMP [--list N]\n");
        return 2;
    }
    int list = 10;
    for (int i = 2; i + 1 < argc; ++i)
        if (std::string(argv[i]) == "--list") list = std::atoi(argv[i + 1]);
    std::ifstream in(argv[1]);
    if (!in) {
        std::fprintf(stderr, "aneu_bench_overlap: cannot read %s\n", argv[1]);
        return 2;
    }
    std::vector<Patch> patches;
    std::string line;
    while (std::getline(in, line)) {
        std::istringstream s(line);
        std::string tag;
        s >> tag;
        if (tag == "patch") {
            patches.emplace_back();
        } else if (tag == "n" && !patches.empty()) {
            double X[3], x[3];
            int iface = 0, cand = 0;
            s >> X[0] >> X[1] >> X[2] >> x[0] >> x[1] >> x[2] >> iface >> cand;
            patches.back().x.emplace_back(x[0], x[1], x[2]);
            patches.back().iface.push_back(iface);
            patches.back().cand.push_back(cand);
        } else if (tag == "e" && !patches.empty()) {
            std::vector<int> e;
            for (int v; s >> v;) e.push_back(v);
            patches.back().elements.push_back(e);
        }
    }
    if (patches.empty()) {
        std::fprintf(stderr, "aneu_bench_overlap: %s: no patch in the dump\n", argv[1]);
        return 2;
    }
    constexpr double ROUNDOFF_MM = 1e-3;  // aneusim's TISSUE_ROUNDOFF_MM
    for (size_t k = 0; k < patches.size(); ++k) {
        const Patch& P = patches[k];
        if (P.elements.empty()) continue;
        Eigen::MatrixX3d x(static_cast<Eigen::Index>(P.x.size()), 3);
        for (size_t a = 0; a < P.x.size(); ++a) x.row(static_cast<Eigen::Index>(a)) = P.x[a].transpose();
        Eigen::MatrixXi E(static_cast<Eigen::Index>(P.elements.size()), static_cast<Eigen::Index>(P.elements[0].size()));
        for (size_t e = 0; e < P.elements.size(); ++e)
            for (size_t c = 0; c < P.elements[e].size(); ++c) E(static_cast<Eigen::Index>(e), static_cast<Eigen::Index>(c)) = P.elements[e][c];
        std::vector<int> query;
        for (size_t a = 0; a < P.x.size(); ++a)
            if (!P.iface[a]) query.push_back(static_cast<int>(a));
        std::vector<double> depth;
        const std::vector<int> held = aneu::fem::nodes_inside_elements(x, E, query, &depth);
        std::vector<size_t> deep;
        for (size_t i = 0; i < query.size(); ++i)
            if (held[i] >= 0 && depth[i] > ROUNDOFF_MM) deep.push_back(i);
        std::sort(deep.begin(), deep.end(), [&](size_t a, size_t b) { return depth[a] > depth[b]; });
        int cands = 0;
        for (size_t i : deep) cands += P.cand[static_cast<size_t>(query[i])];
        std::printf("patch %zu: %zu nodes, %zu elements; %zu nodes off the interface more than 1 um inside an element not their own (%d blade candidates), deepest %.4f mm\n",
                    k, P.x.size(), P.elements.size(), deep.size(), cands, deep.empty() ? 0.0 : depth[deep[0]]);
        for (size_t r = 0; r < deep.size() && static_cast<int>(r) < list; ++r)
            std::printf("  node %d depth %.4f mm element %d candidate %d\n", query[deep[r]], depth[deep[r]], held[deep[r]], P.cand[static_cast<size_t>(query[deep[r]])]);
    }
    return 0;
}
