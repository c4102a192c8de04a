// [imu.transport] types udp and tcp_server (issue 27; drivers/net_transport.hpp):
// keys and defaults reach the transport config, wrong values and a CAN
// protocol are refused naming the key, and two devices on one local port are
// refused by the scene check before anything opens.
#include <gtest/gtest.h>

#include <string>

#include "daemon/scene/scene_check.hpp"
#include "daemon/scene/scene_config.hpp"
#include "daemon/scene/scene_runner.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace unity_scene_test_net_transport_keys {
namespace imuemu { using namespace ::imuemu; }

namespace imuemu {
namespace {

std::string net_scene(const std::string& protocol, const std::string& transport, const std::string& second = "") {
  return "[scene]\nname = \"t\"\nphysics = \"flat\"\n[trajectory]\nsource = \"sample:static\"\nduration_s = 10\n"
         "[[imu]]\nname = \"a\"\nrate_hz = 100\nprotocol = \"" + protocol + "\"\n[imu.transport]\n" + transport +
         (second.empty() ? "" : "[[imu]]\nname = \"b\"\nrate_hz = 100\nprotocol = \"" + protocol +
                                    "\"\n[imu.transport]\n" + second);
}

TEST(NetTransportSceneKeys, UdpAndTcpServerKeysAndDefaults) {
  const scene::SceneConfig u =
      scene::parse_scene_text(net_scene("mavlink2", "type = \"udp\"\nhost = \"10.1.2.3\"\nbind_port = 14555\n"),
                              "t.toml", "/tmp");
  const scene::TransportConfig& ut = u.imus.at(0).transport;
  EXPECT_EQ(ut.type, scene::TransportType::udp);
  EXPECT_EQ(ut.net.host, "10.1.2.3");
  EXPECT_EQ(ut.net.port, 14550) << "MAVLink's ground-station port by default";
  EXPECT_EQ(ut.net.bind_port, 14555);
  const scene::SceneConfig s =
      scene::parse_scene_text(net_scene("mip", "type = \"tcp_server\"\nport = 4560\n"), "t.toml", "/tmp");
  const scene::TransportConfig& st = s.imus.at(0).transport;
  EXPECT_EQ(st.type, scene::TransportType::tcp_server);
  EXPECT_EQ(st.net.host, "0.0.0.0");
  EXPECT_EQ(st.net.port, 4560);
}

TEST(NetTransportSceneKeys, WrongValuesAreRefusedNamingTheKey) {
  const std::pair<std::string, std::string> cases[] = {
      {net_scene("mavlink2", "type = \"tcp_server\"\n"), "port"},
      {net_scene("mavlink2", "type = \"tcp_server\"\nport = 0\n"), "port"},
      {net_scene("mavlink2", "type = \"udp\"\nport = 70000\n"), "port"},
      {net_scene("mavlink2", "type = \"udp\"\nlink = \"/tmp/x\"\n"), "link"},
      {net_scene("dronecan", "type = \"udp\"\n"), "type"},
  };
  for (const auto& [text, key] : cases) {
    try {
      (void)scene::parse_scene_text(text, "t.toml", "/tmp");
      ADD_FAILURE() << "accepted: " << text;
    } catch (const std::exception& e) {
      EXPECT_NE(std::string(e.what()).find(key), std::string::npos) << e.what();
    }
  }
}

TEST(NetTransportSceneKeys, TwoDevicesOnOneLocalPortAreRefusedBeforeAnythingOpens) {
  scene::RunnerOptions options;
  const scene::SceneConfig same_tcp = scene::parse_scene_text(
      net_scene("mavlink2", "type = \"tcp_server\"\nport = 4560\n", "type = \"tcp_server\"\nport = 4560\n"), "t.toml",
      "/tmp");
  try {
    scene::check_start_paths(same_tcp, options, "");
    ADD_FAILURE() << "two tcp servers on port 4560 accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("local tcp port 4560 is also imu 'a''s"), std::string::npos) << e.what();
  }
  const scene::SceneConfig two_udp_kernel_ports = scene::parse_scene_text(
      net_scene("mavlink2", "type = \"udp\"\n", "type = \"udp\"\n"), "t.toml", "/tmp");
  EXPECT_NO_THROW(scene::check_start_paths(two_udp_kernel_ports, options, ""))
      << "bind_port 0: each gets its own port from the kernel";
}

}  // namespace
}  // namespace imuemu
}  // namespace unity_scene_test_net_transport_keys
