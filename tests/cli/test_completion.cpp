// `imuemu completion` in bash: the script it prints is sourced and its
// completion function called as bash would call it (COMP_WORDS, COMP_CWORD),
// and what it offers is checked against the command line's own --help:
// every command at the top, every long option of a command (and of a nested
// one: `fault inject`), nothing that --help does not list.
#include <gtest/gtest.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <fstream>
#include <regex>
#include <set>
#include <sstream>
#include <string>

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace unity_cli_test_completion {
namespace imuemu { using namespace ::imuemu; }

std::string run_for_completion(const std::string& command) {
  FILE* pipe = ::popen(command.c_str(), "r");
  if (pipe == nullptr) return {};
  std::string out;
  std::array<char, 4096> buffer{};
  std::size_t got = 0;
  while ((got = std::fread(buffer.data(), 1, buffer.size(), pipe)) > 0) out.append(buffer.data(), got);
  ::pclose(pipe);
  return out;
}

// The words the completion offers after `line` (the last word is the one
// being completed; "" completes a new word).
std::set<std::string> completions_for(const std::string& script, const std::string& line) {
  std::ostringstream bash;
  bash << "source " << script << "\nCOMP_WORDS=(" << line << ")\n";
  if (!line.empty() && line.back() == ' ') bash << "COMP_WORDS+=(\"\")\n";
  bash << "COMP_CWORD=$((${#COMP_WORDS[@]} - 1))\n_imuemu\nprintf '%s\\n' \"${COMPREPLY[@]}\"\n";
  // Per process: ctest runs this file's tests at once, each in its own process.
  const std::string file = ::testing::TempDir() + "imuemu_completion_driver." + std::to_string(::getpid()) + ".sh";
  std::ofstream(file) << bash.str();
  std::set<std::string> words;
  std::istringstream lines(run_for_completion("bash " + file));
  for (std::string w; std::getline(lines, w);)
    if (!w.empty()) words.insert(w);
  std::remove(file.c_str());
  return words;
}

std::set<std::string> long_options_in_help(const std::string& command) {
  const std::string help = run_for_completion(std::string(IMUEMU_CLI_PATH) + " " + command + " --help 2>&1");
  std::set<std::string> out;
  const std::regex option(R"((^|[ ,])(--[a-zA-Z0-9][a-zA-Z0-9-]*))");
  std::istringstream lines(help);
  for (std::string l; std::getline(lines, l);) {
    // Option lines start with blanks then '-' (CLI11's layout).
    if (l.find_first_not_of(' ') == std::string::npos || l[l.find_first_not_of(' ')] != '-') continue;
    const std::string head = l.substr(0, l.find("  ", l.find_first_not_of(' ')));
    for (std::sregex_iterator it(head.begin(), head.end(), option), end; it != end; ++it) out.insert((*it)[2]);
  }
  return out;
}

class Completion : public ::testing::Test {
 protected:
  void SetUp() override {
    script_ = ::testing::TempDir() + "imuemu_completion." + std::to_string(::getpid()) + ".bash";
    std::ofstream(script_) << run_for_completion(std::string(IMUEMU_CLI_PATH) + " completion");
  }
  void TearDown() override { std::remove(script_.c_str()); }
  std::string script_;
};

TEST_F(Completion, OffersEveryCommandAndCompletesAPrefix) {
  const std::set<std::string> top = completions_for(script_, "imuemu ");
  for (const char* command : {"generate", "verify", "emit", "listen", "allan", "send", "fault", "status", "completion",
                              "protocol-options"})
    EXPECT_TRUE(top.count(command)) << command;
  EXPECT_EQ(completions_for(script_, "imuemu gen"), (std::set<std::string>{"generate"}));
  EXPECT_EQ(completions_for(script_, "imuemu fault "), (std::set<std::string>{"inject", "list", "clear"}));
}

TEST_F(Completion, OffersExactlyTheLongOptionsOfTheCommandsHelp) {
  for (const std::string command : {"generate", "emit", "listen", "allan", "fault inject", "bench timing"}) {
    const std::set<std::string> help = long_options_in_help(command);
    ASSERT_GT(help.size(), 2u) << command;
    std::set<std::string> offered;
    for (const std::string& w : completions_for(script_, "imuemu " + command + " --")) offered.insert(w);
    EXPECT_EQ(offered, help) << command;
  }
  // A word typed between options does not lose the command path.
  EXPECT_TRUE(completions_for(script_, "imuemu generate --in x.csv --ou").count("--out"));
}

}  // namespace unity_cli_test_completion
