// Numerical derivatives of thesis Proposition 3.29 (Eq. 3.71-3.74) on a
// uniformly sampled sequence, with the thesis' choice at the ends (§3.7):
// forward difference (3.71) at the first sample, backward (3.72) at the last,
// centred (3.73) at the second and second-to-last, five-point (3.74) elsewhere.
#pragma once

#include <span>

#include "core/types.hpp"

namespace imuemu::derivatives {

// Derivative of sample i of f (step h_s seconds); f needs >= 2 samples.
Vec3 derivative_at(std::span<const Vec3> f, double h_s, std::size_t i);
void differentiate(std::span<const Vec3> f, double h_s, std::span<Vec3> out);

}  // namespace imuemu::derivatives
