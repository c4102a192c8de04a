// The man pages (docs/man/imuemu.1, docs/man/imuemud.8, written by hand) and
// the programs' --help agree: for imuemu, each of its commands (and their
// subcommands: bench timing, fault inject, ...) and imuemud, the long options
// --help lists are exactly the ones the man page lists for that command.
//
// --help is CLI11's layout: option lines start with two blanks and '-'
// ("  -h,--help ...", "  --in TEXT ..."), in groups ending in "options:" or
// "Options:"; commands under "Subcommands:". The man page's layout: one
// `.SS "imuemu COMMAND"` per command (the top-level options under `.SH
// OPTIONS` of imuemu.1, imuemud's under `.SH OPTIONS` of imuemud.8), one
// `.TP` per option whose tag line (the line after `.TP`) names it as
// `\-\-name`. Options mentioned in running text do not count.
#include <gtest/gtest.h>

#include <sys/wait.h>

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <map>
#include <optional>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <vector>

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace unity_cli_test_man_pages {
namespace imuemu { using namespace ::imuemu; }

namespace {

std::string help_of(const std::string& program, const std::string& command) {
  const std::string cmd = program + (command.empty() ? "" : " " + command) + " --help 2>&1";
  std::string out;
  FILE* p = ::popen(cmd.c_str(), "r");
  if (!p) return out;
  char buf[4096];
  std::size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, p)) > 0) out.append(buf, n);
  const int status = ::pclose(p);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << cmd << "\n" << out;
  return out;
}

struct Help {
  std::set<std::string> options;       // long names, "--in"
  std::vector<std::string> subcommands;
};

Help parse_help(const std::string& text) {
  Help h;
  std::istringstream in(text);
  std::string line, section;
  const std::regex heading(R"(^\S.*:$)");
  const std::regex option_line(R"(^  (-[^ ]+))");
  const std::regex subcommand_line(R"(^  ([a-z][a-z0-9-]*)\s)");
  while (std::getline(in, line)) {
    if (std::regex_match(line, heading)) {
      section = line;
      continue;
    }
    std::smatch m;
    if (section == "Subcommands:") {
      if (std::regex_search(line, m, subcommand_line)) h.subcommands.push_back(m[1]);
    } else if (section != "Positionals:" && std::regex_search(line, m, option_line)) {
      std::stringstream names(m[1].str());
      for (std::string name; std::getline(names, name, ',');)
        if (name.rfind("--", 0) == 0) h.options.insert(name);
    }
  }
  return h;
}

// Man page: command key ("" for the page's own program) -> long options of its .TP tags.
std::map<std::string, std::set<std::string>> parse_man(const std::string& path, const std::string& program) {
  std::map<std::string, std::set<std::string>> pages;
  std::ifstream in(path);
  EXPECT_TRUE(in) << path;
  std::string line;
  std::optional<std::string> key;  // nullopt: a section without options
  bool tag_next = false;
  const std::regex long_option(R"(\\-\\-((?:[A-Za-z0-9]|\\-)+))");
  while (std::getline(in, line)) {
    if (line.rfind(".SH", 0) == 0) {
      key = line.find("OPTIONS") != std::string::npos ? std::optional<std::string>("") : std::nullopt;
      tag_next = false;
      continue;
    }
    if (line.rfind(".SS", 0) == 0) {
      std::string title = line.substr(3);
      title.erase(std::remove(title.begin(), title.end(), '"'), title.end());
      title.erase(0, title.find_first_not_of(' '));
      if (title.rfind(program + " ", 0) == 0) {
        key = title.substr(program.size() + 1);
        pages[*key];  // a command with no options beyond --help still has a section
      } else {
        key = std::nullopt;
      }
      tag_next = false;
      continue;
    }
    if (line.rfind(".TP", 0) == 0) {
      tag_next = true;
      continue;
    }
    if (tag_next && key) {
      for (std::sregex_iterator it(line.begin(), line.end(), long_option), end; it != end; ++it) {
        std::string name = (*it)[1].str();
        std::string plain;
        for (std::size_t i = 0; i < name.size(); ++i)
          if (!(name[i] == '\\' && i + 1 < name.size() && name[i + 1] == '-')) plain += name[i];
        pages[*key].insert("--" + plain);
      }
    }
    tag_next = false;
  }
  return pages;
}

std::string list(const std::set<std::string>& s) {
  std::string out;
  for (const std::string& x : s) out += (out.empty() ? "" : " ") + x;
  return out;
}

// Every command path of a program: "" and "generate", "bench", "bench timing", ...
void collect(const std::string& program, const std::string& command, std::map<std::string, std::set<std::string>>& out) {
  const Help h = parse_help(help_of(program, command));
  out[command] = h.options;
  for (const std::string& sub : h.subcommands) collect(program, command.empty() ? sub : command + " " + sub, out);
}

void expect_agree(const std::string& program, const std::string& name, const std::string& man_path) {
  std::map<std::string, std::set<std::string>> help;
  collect(program, "", help);
  const std::map<std::string, std::set<std::string>> man = parse_man(man_path, name);
  ASSERT_GT(help.size(), 0u);
  for (const auto& [command, options] : help) {
    const std::string who = name + (command.empty() ? "" : " " + command);
    const auto it = man.find(command);
    if (it == man.end()) {
      ADD_FAILURE() << man_path << ": no section for '" << who << "' (--help lists " << list(options) << ")";
      continue;
    }
    std::set<std::string> only_help, only_man;
    for (const std::string& o : options)
      if (!it->second.count(o)) only_help.insert(o);
    for (const std::string& o : it->second)
      if (!options.count(o)) only_man.insert(o);
    EXPECT_TRUE(only_help.empty()) << who << ": in --help, not in " << man_path << ": " << list(only_help);
    EXPECT_TRUE(only_man.empty()) << who << ": in " << man_path << ", not in --help: " << list(only_man);
  }
  for (const auto& [command, options] : man)
    EXPECT_TRUE(help.count(command)) << man_path << ": a section for '" << name << " " << command
                                     << "', which --help does not list as a command";
}

const std::string kManDir = std::string(IMUEMU_SOURCE_DIR) + "/docs/man/";

TEST(ManPages, ImuemuAgreesWithItsHelp) {
  expect_agree(IMUEMU_CLI_PATH, "imuemu", kManDir + "imuemu.1");
}

TEST(ManPages, ImuemudAgreesWithItsHelp) {
  expect_agree(IMUEMUD_PATH, "imuemud", kManDir + "imuemud.8");
}

// The checker itself can fail: an option only in --help, one only in the page.
TEST(ManPages, TheCheckSeesBothDirections) {
  const Help h = parse_help("Usage: x [OPTIONS]\n\nOptions:\n  -h,--help   Print\n  --in TEXT   In\n\nSubcommands:\n  go   Go\n");
  EXPECT_EQ(h.options, (std::set<std::string>{"--help", "--in"}));
  EXPECT_EQ(h.subcommands, (std::vector<std::string>{"go"}));
  const std::string page = ::testing::TempDir() + "/man_check.1";
  std::ofstream(page) << ".TH X 1\n.SH OPTIONS\n.TP\n\\fB\\-h\\fR, \\fB\\-\\-help\\fR\nHelp, see \\-\\-other\n"
                         ".SS \"x go\"\nGo.\n.TP\n\\fB\\-\\-fast\\-mode\\fR \\fIN\\fR\nFast.\n.SH SEE ALSO\n.TP\n\\-\\-not\\-an\\-option\n";
  const auto man = parse_man(page, "x");
  ASSERT_EQ(man.size(), 2u);
  EXPECT_EQ(man.at(""), (std::set<std::string>{"--help"}));
  EXPECT_EQ(man.at("go"), (std::set<std::string>{"--fast-mode"}));
}

}  // namespace
}  // namespace unity_cli_test_man_pages
