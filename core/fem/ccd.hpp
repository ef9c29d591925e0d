// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// Additive continuous collision detection (Li, Kaufman & Jiang 2021), shared by the walls' and the blades'
/// contact (ContactBody::max_step, ClipBody::max_step). Internal to core/fem.

namespace aneu::fem::detail {

/// The largest t ≤ alpha along a step at which a pair's distance dist(t) (dist(0) = d0 > 0) is still at least a
/// tenth of d0, given that the distance falls at most as fast as l per unit of t: advancing by 0.9 dist / l at a
/// time never passes the contact, and stops where the distance is a tenth of its start.
template <class Dist>
double additive_ccd(double d0, double l, double alpha, Dist&& dist) {
    constexpr double SHRINK = 0.1;
    if (!(l > 0) || (1 - SHRINK) * d0 >= alpha * l) return alpha;  // cannot come near within the step
    // The first advance, (1 − SHRINK) d0 / l, cannot bring it below SHRINK · d0.
    double t = 0, tl = (1 - SHRINK) * d0 / l;
    for (int it = 0;; ++it) {
        if (t + tl >= alpha) return alpha;  // reaches α without coming near
        const double dn = dist(t + tl);
        if ((it > 0 && dn < SHRINK * d0) || it == 10000) return t;
        t += tl;
        tl = 0.9 * dn / l;
    }
}

}  // namespace aneu::fem::detail
