// `imuemu --version` and `imuemud --version` (issue 32): the project version
// from CMakeLists.txt's project() and the git commit the tree was configured
// from, exit 0, nothing else (a subcommand is not required for it).
#include <gtest/gtest.h>

#include <sys/wait.h>

#include <array>
#include <cstdio>
#include <fstream>
#include <regex>
#include <sstream>
#include <string>

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace unity_cli_test_version {
namespace imuemu { using namespace ::imuemu; }

namespace {

std::pair<std::string, int> run_version(const std::string& program) {
  std::string out;
  FILE* pipe = ::popen((program + " --version 2>&1").c_str(), "r");
  if (pipe == nullptr) return {"", -1};
  std::array<char, 256> buf{};
  while (std::fgets(buf.data(), buf.size(), pipe) != nullptr) out += buf.data();
  const int status = ::pclose(pipe);
  return {out, WIFEXITED(status) ? WEXITSTATUS(status) : -1};
}

// The version CMakeLists.txt declares, read from the file itself.
std::string declared_version() {
  std::ifstream in(std::string(IMUEMU_SOURCE_DIR) + "/CMakeLists.txt");
  std::stringstream text;
  text << in.rdbuf();
  std::smatch m;
  const std::string s = text.str();
  return std::regex_search(s, m, std::regex(R"(project\(imuemu VERSION ([0-9.]+))")) ? m[1].str() : "?";
}

TEST(Version, BothProgramsPrintTheDeclaredVersionAndTheCommit) {
  const std::string version = declared_version();
  ASSERT_NE(version, "?");
  for (const auto& [program, name] : {std::pair<std::string, std::string>{IMUEMU_CLI_PATH, "imuemu"},
                                      std::pair<std::string, std::string>{IMUEMUD_PATH, "imuemud"}}) {
    const auto [out, code] = run_version(program);
    EXPECT_EQ(code, 0) << out;
    EXPECT_TRUE(std::regex_match(out, std::regex(name + " " + std::regex_replace(version, std::regex(R"(\.)"), R"(\.)") +
                                                 R"( \(git ([0-9a-f]{12}|unknown)\)\n)")))
        << out;
  }
}

}  // namespace
}  // namespace unity_cli_test_version
