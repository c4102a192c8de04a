// [imu.device] for the CAN devices (issue 27, docs/can-device.md): identity
// keys reach the DroneCAN / J1939 options; bad values are refused.
#include <gtest/gtest.h>

#include <string>

#include "daemon/scene/scene_config.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace unity_scene_test_can_device_keys {
namespace imuemu { using namespace ::imuemu; }

namespace imuemu {
namespace {

std::string can_scene(const std::string& protocol, const std::string& device_table) {
  return "[scene]\nname = \"t\"\nphysics = \"flat\"\n[trajectory]\nsource = \"sample:static\"\nduration_s = 10\n"
         "[[imu]]\nname = \"a\"\nrate_hz = 100\nprotocol = \"" + protocol + "\"\n[imu.transport]\ntype = \"null\"\n" +
         device_table;
}

TEST(CanDeviceSceneKeys, DroneCanIdentityAndPowerUp) {
  const scene::SceneConfig c = scene::parse_scene_text(
      can_scene("dronecan", "[imu.device]\nnode_name = \"org.example.imu\"\nsoftware_version = \"2.3\"\n"
                            "hardware_version = \"4.5\"\nvcs_commit = 3735928559\n"
                            "unique_id = \"000102030405060708090a0b0c0d0e0f\"\npower_up_initialization = true\n"),
      "t.toml", "/tmp");
  const drivers::dronecan::DroneCanOptions& d = c.imus.at(0).can_options.dronecan;
  EXPECT_EQ(d.name, "org.example.imu");
  EXPECT_EQ(d.software_major, 2);
  EXPECT_EQ(d.software_minor, 3);
  EXPECT_EQ(d.hardware_major, 4);
  EXPECT_EQ(d.hardware_minor, 5);
  EXPECT_EQ(d.software_vcs_commit, 0xDEADBEEFu);
  ASSERT_TRUE(d.unique_id.has_value());
  for (unsigned i = 0; i < 16; ++i) EXPECT_EQ((*d.unique_id)[i], i);
  EXPECT_TRUE(d.initialization_at_power_up);

  const scene::SceneConfig dflt = scene::parse_scene_text(can_scene("dronecan", ""), "t.toml", "/tmp");
  EXPECT_EQ(dflt.imus.at(0).can_options.dronecan.name, "com.imuemu.imu");
  EXPECT_FALSE(dflt.imus.at(0).can_options.dronecan.initialization_at_power_up);
  for (const std::string& bad : {can_scene("dronecan", "[imu.device]\nunique_id = \"0011\"\n"),
                                 can_scene("dronecan", "[imu.device]\nsoftware_version = \"1.2.3\"\n"),
                                 can_scene("dronecan", "[imu.device]\nnode_name = \"\"\n"),
                                 can_scene("dronecan", "[imu.device]\nmodel_name = \"x\"\n")}) {
    EXPECT_THROW((void)scene::parse_scene_text(bad, "t.toml", "/tmp"), std::exception) << bad;
  }
}

TEST(CanDeviceSceneKeys, J1939Identification) {
  const scene::SceneConfig c = scene::parse_scene_text(
      can_scene("j1939", "[imu.device]\nmake = \"ACME\"\nmodel = \"IMU-9\"\nserial_number = \"SN1\"\n"
                         "unit_number = \"7\"\nsoftware_id = \"fw 3.1\"\n"),
      "t.toml", "/tmp");
  const drivers::j1939::J1939Options& j = c.imus.at(0).can_options.j1939;
  EXPECT_EQ(j.make, "ACME");
  EXPECT_EQ(j.model, "IMU-9");
  EXPECT_EQ(j.serial_number, "SN1");
  EXPECT_EQ(j.unit_number, "7");
  ASSERT_EQ(j.software_ids.size(), 1u);
  EXPECT_EQ(j.software_ids[0], "fw 3.1");
  for (const std::string& bad : {can_scene("j1939", "[imu.device]\nmake = \"TOOLONG\"\n"),
                                 can_scene("j1939", "[imu.device]\nmodel = \"a*b\"\n")}) {
    EXPECT_THROW((void)scene::parse_scene_text(bad, "t.toml", "/tmp"), std::exception) << bad;
  }
}

}  // namespace
}  // namespace imuemu
}  // namespace unity_scene_test_can_device_keys
