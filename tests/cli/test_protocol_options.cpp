// `imuemu protocol-options` and docs/scene-format.md (the source of
// imuemu-scene(5)): the document's reference block is exactly what the
// command prints from the option table, and the command lists every row of
// the table, so a key added to the code and not to the manual fails here.
#include <gtest/gtest.h>

#include <array>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <string>

#include "drivers/protocols/protocol_options.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace unity_cli_test_protocol_options {
namespace imuemu { using namespace ::imuemu; }
namespace drivers = ::imuemu::drivers;

std::string output_of_protocol_options(const std::string& args) {
  const std::string command = std::string(IMUEMU_CLI_PATH) + " protocol-options " + args + " 2>&1";
  FILE* pipe = ::popen(command.c_str(), "r");
  if (pipe == nullptr) return {};
  std::string out;
  std::array<char, 4096> buffer{};
  std::size_t got = 0;
  while ((got = std::fread(buffer.data(), 1, buffer.size(), pipe)) > 0) out.append(buffer.data(), got);
  const int status = ::pclose(pipe);
  EXPECT_EQ(status, 0) << command;
  return out;
}

std::string trim_newlines(std::string s) {
  while (!s.empty() && s.front() == '\n') s.erase(s.begin());
  while (!s.empty() && s.back() == '\n') s.pop_back();
  return s;
}

TEST(ProtocolOptions, TheSceneDocumentsReferenceBlockIsWhatTheCommandPrints) {
  std::ifstream in(std::string(IMUEMU_SOURCE_DIR) + "/docs/scene-format.md");
  ASSERT_TRUE(in);
  std::stringstream text;
  text << in.rdbuf();
  const std::string doc = text.str();
  const std::string begin = "<!-- BEGIN imuemu protocol-options --markdown -->";
  const std::string end = "<!-- END imuemu protocol-options --markdown -->";
  const std::size_t b = doc.find(begin);
  const std::size_t e = doc.find(end);
  ASSERT_NE(b, std::string::npos);
  ASSERT_NE(e, std::string::npos);
  ASSERT_LT(b, e);
  const std::string block = trim_newlines(doc.substr(b + begin.size(), e - b - begin.size()));
  EXPECT_EQ(block, trim_newlines(output_of_protocol_options("--markdown")))
      << "docs/scene-format.md's protocol option reference is out of date: "
         "python3 scripts/update_protocol_options_doc.py rewrites it";
}

TEST(ProtocolOptions, EveryRowOfTheTableIsListedWithItsRangeAndDefault) {
  const std::string markdown = output_of_protocol_options("--markdown");
  const std::string plain = output_of_protocol_options("");
  std::size_t rows = 0;
  for (const drivers::ProtocolOption& o : drivers::protocol_option_table()) {
    ++rows;
    const std::string table = drivers::protocol_option_table_name(o.protocol);
    // The row sits under its own table's heading, before the next one.
    const std::size_t heading = markdown.find("#### `[imu." + table + "]`");
    ASSERT_NE(heading, std::string::npos) << table;
    const std::size_t next = markdown.find("#### ", heading + 1);
    const std::string section = markdown.substr(heading, next == std::string::npos ? std::string::npos : next - heading);
    EXPECT_NE(section.find("| `" + o.key + "` |"), std::string::npos) << table << "." << o.key;
    std::string allowed = drivers::allowed_text(o);
    EXPECT_NE(plain.find("  " + o.key + " ("), std::string::npos) << o.key;
    EXPECT_NE(plain.find(allowed + "; default " + o.default_text), std::string::npos) << o.key << ": " << allowed;
  }
  EXPECT_GT(rows, 50u);
}

}  // namespace unity_cli_test_protocol_options
