// imuemu's main(): the tool is daemon/cli/imuemu_app.cpp. Only this file
// sees IMUEMU_VERSION_TEXT, so a new commit recompiles one small file.
#include "daemon/cli/imuemu_app.hpp"

int main(int argc, char** argv) { return imuemu::cli::run_imuemu(argc, argv, IMUEMU_VERSION_TEXT); }
