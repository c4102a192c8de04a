#include "core/derivatives.hpp"

#include <stdexcept>

namespace imuemu::derivatives {

Vec3 derivative_at(std::span<const Vec3> f, double h_s, std::size_t i) {
  const std::size_t n = f.size();
  if (n < 2) throw std::invalid_argument("a derivative needs at least two samples");
  if (i == 0) return (f[1] - f[0]) / h_s;                 // Eq. 3.71
  if (i == n - 1) return (f[n - 1] - f[n - 2]) / h_s;     // Eq. 3.72
  if (i == 1 || i == n - 2) return (f[i + 1] - f[i - 1]) / (2.0 * h_s);  // Eq. 3.73
  // Eq. 3.74: (-f(x+2h) + 8 f(x+h) - 8 f(x-h) + f(x-2h)) / 12h
  return (-f[i + 2] + 8.0 * (f[i + 1] - f[i - 1]) + f[i - 2]) / (12.0 * h_s);
}

void differentiate(std::span<const Vec3> f, double h_s, std::span<Vec3> out) {
  if (out.size() != f.size()) throw std::invalid_argument("differentiate: output size mismatch");
  for (std::size_t i = 0; i < f.size(); ++i) out[i] = derivative_at(f, h_s, i);
}

}  // namespace imuemu::derivatives
