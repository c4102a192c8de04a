// Where the installed program finds its data: PREFIX/share/imuemu beside
// PREFIX/bin (or sbin), found from the running executable, so no path of the
// build machine is compiled in. The Debian package installs under /usr
// (/usr/share/imuemu: the example scenes and their data under config/, the
// Allan plotting script); a build tree copies what it needs to the same
// place relative to its daemon/ directory (build/<flavour>/share/imuemu).
#pragma once

#include <filesystem>

namespace imuemu::io {

// PREFIX/share/imuemu for the executable /proc/self/exe = PREFIX/DIR/NAME;
// /usr/share/imuemu if the executable cannot be found.
std::filesystem::path installed_data_dir();

}  // namespace imuemu::io
