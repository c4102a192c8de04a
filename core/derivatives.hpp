// Numerical derivatives of thesis Proposition 3.29 (Eq. 3.71-3.74) on a
// uniformly sampled sequence, with the thesis' choice at the ends (§3.7):
// forward difference (3.71) at the first sample, backward (3.72) at the last,
// centred (3.73) at the second and second-to-last, five-point (3.74) elsewhere.
#pragma once

#include <span>

#include "core/types.hpp"

namespace imuemu::derivatives {

// Derivative at index i of a sequence of n >= 2 samples spaced h_s seconds,
// read through `at(j)` (so callers can difference values they compute on the
// fly, e.g. logs in a chart centred at sample i).
template <typename At>
Vec3 stencil(const At& at, std::size_t i, std::size_t n, double h_s) {
  if (i == 0) return (at(1) - at(0)) / h_s;                                    // Eq. 3.71
  if (i == n - 1) return (at(n - 1) - at(n - 2)) / h_s;                        // Eq. 3.72
  if (i == 1 || i == n - 2) return (at(i + 1) - at(i - 1)) / (2.0 * h_s);      // Eq. 3.73
  return (-at(i + 2) + 8.0 * (at(i + 1) - at(i - 1)) + at(i - 2)) / (12.0 * h_s);  // Eq. 3.74
}

// Derivative of sample i of f (step h_s seconds); f needs >= 2 samples.
Vec3 derivative_at(std::span<const Vec3> f, double h_s, std::size_t i);
void differentiate(std::span<const Vec3> f, double h_s, std::span<Vec3> out);

}  // namespace imuemu::derivatives
