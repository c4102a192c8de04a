#include "io/installed_paths.hpp"

#include <system_error>

namespace imuemu::io {

std::filesystem::path installed_data_dir() {
  std::error_code ec;
  const std::filesystem::path self = std::filesystem::read_symlink("/proc/self/exe", ec);
  if (ec || !self.has_parent_path()) return "/usr/share/imuemu";
  return self.parent_path().parent_path() / "share" / "imuemu";
}

}  // namespace imuemu::io
