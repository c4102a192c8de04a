#include "core/derivatives.hpp"

#include <stdexcept>

namespace imuemu::derivatives {

Vec3 derivative_at(std::span<const Vec3> f, double h_s, std::size_t i) {
  if (f.size() < 2) throw std::invalid_argument("a derivative needs at least two samples");
  return stencil([&](std::size_t j) -> const Vec3& { return f[j]; }, i, f.size(), h_s);
}

void differentiate(std::span<const Vec3> f, double h_s, std::span<Vec3> out) {
  if (out.size() != f.size()) throw std::invalid_argument("differentiate: output size mismatch");
  for (std::size_t i = 0; i < f.size(); ++i) out[i] = derivative_at(f, h_s, i);
}

}  // namespace imuemu::derivatives
