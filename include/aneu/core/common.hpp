// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// The project's one definition of π, of a percentile and of elapsed time (issue #16: six π constants, three
/// percentile conventions and five elapsed-time helpers before).
#include <algorithm>
#include <chrono>
#include <cstddef>
#include <vector>

namespace aneu {

inline constexpr double PI = 3.14159265358979323846;
/// Degrees to radians: `angle_deg * DEG`.
inline constexpr double DEG = PI / 180.0;

/// The q-quantile (q in [0, 1]) by the lower nearest rank: element ⌊q·(n−1)⌋ of the sorted values, so q = 0
/// is the minimum, q = 1 the maximum and q = 0.5 the lower median. 0 for no values.
template <class T>
double percentile(std::vector<T> v, double q) {
    if (v.empty()) return 0.0;
    const auto k = static_cast<std::size_t>(std::clamp(q, 0.0, 1.0) * static_cast<double>(v.size() - 1));
    std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
    return static_cast<double>(v[k]);
}

/// Wall-clock seconds since construction (or the last restart), on the monotonic clock.
class Stopwatch {
public:
    using Clock = std::chrono::steady_clock;
    Stopwatch() : m_t0(Clock::now()) {}
    double seconds() const { return std::chrono::duration<double>(Clock::now() - m_t0).count(); }
    /// Seconds so far, and starts again.
    double lap() {
        const auto now = Clock::now();
        const double s = std::chrono::duration<double>(now - m_t0).count();
        m_t0 = now;
        return s;
    }
    Clock::time_point started() const { return m_t0; }

private:
    Clock::time_point m_t0;
};

}  // namespace aneu
