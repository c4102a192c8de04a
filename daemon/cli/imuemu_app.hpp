// The imuemu command-line tool as a function (imuemu_app.cpp), so its main()
// is one line and the CLI11 code compiles in the cli room's batch.
#pragma once

namespace imuemu::cli {

// Parses argv, runs the subcommand, returns the process's exit code.
// version_text: what --version prints after "imuemu ".
int run_imuemu(int argc, char** argv, const char* version_text);

}  // namespace imuemu::cli
