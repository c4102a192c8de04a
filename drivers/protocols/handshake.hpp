// The driver's side of a device's start-up (issue 27, `imuemu listen
// --handshake`): the requests a common driver writes to an IMU when it
// connects, and a reader of the replies that says what each one answered.
// A bench engineer runs it against imuemud (or a real device) to see what
// their driver will see, before the driver itself is on the bench.
//
// Sequences, read from the drivers' sources (the same ones the device room's
// replay tests cite):
//  - mip: the mip_sdk examples (LORD-MicroStrain/mip_sdk e5a847d8,
//    7-series device_info / stream_imu): Ping (0x01,0x01), Set To Idle
//    (0x01,0x02), Get Device Information (0x01,0x03 -> 0x81), Get Device
//    Descriptors (0x01,0x04 -> 0x82), Get Base Rate of set 0x80 (0x0C,0x0E
//    -> 0x8E), Message Format of set 0x80 (0x0C,0x0F -> 0x8F), Resume
//    (0x01,0x06). One change: the message format is READ (function 0x02),
//    not written, so the stream the device was configured with is the stream
//    `listen` then decodes (the example writes accel + gyro at decimation 100).
//  - mavlink2: what a ground station sends a new component (QGroundControl
//    0019ddbe, ParameterManager / Vehicle): its HEARTBEAT (MAV_TYPE_GCS),
//    REQUEST_MESSAGE (MAV_CMD 512) for AUTOPILOT_VERSION (148), and
//    PARAM_REQUEST_LIST, then the device's PARAM_VALUEs until param_count.
//  - vectornav: the registers the VectorNav SDK's connect and PX4's
//    src/drivers/ins/vectornav init() read (1-4), then 6 and 75-77, all
//    read (VectorNavClient in handshake.cpp).
//  - sbg: sbgEComExample's GET /api/v1/info, the CMD_INFO of ellipseLegacy,
//    PX4 and ArduPilot, and an OUTPUT_CONF read (SbgClient in handshake.cpp).
//  - xsens: xspublic's (Xsens' ROS driver) connect and configure sequence:
//    GotoConfig, ReqDID, ReqProductCode, ReqHardwareVersion, ReqFWRev,
//    SetOutputConfiguration, GotoMeasurement (XsensClient in handshake.cpp).
// Frames are built here from the protocol documents ([DCP] MicroStrain's
// MIP Data Communications Protocol manuals; [G] the MAVLink developer guide,
// [X] common.xml); the replies are read with the same framing rules.
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

namespace imuemu::drivers::handshake {

// One step as it ended.
struct StepResult {
  std::string step;       // "Ping (0x01,0x01)"
  bool answered = false;  // a reply to this step arrived before the timeout
  bool accepted = false;  // and it said yes (MIP ACK 0x00, MAV_RESULT_ACCEPTED, parameters complete)
  std::string reply;      // what it said, in words ("ACK", "NACK 0x01 (unknown command)", "model ...")
  double latency_ms = 0;  // request written -> reply complete
};

class Client {
 public:
  virtual ~Client() = default;
  virtual std::size_t step_count() const = 0;
  virtual std::string step_name(std::size_t step) const = 0;
  // The bytes to write for `step` (empty: nothing to write, only wait).
  virtual std::vector<std::uint8_t> request(std::size_t step) = 0;
  // Bytes read from the device while `step` waits (stream packets among
  // them are skipped). Returns true once the step's reply is complete and
  // fills `result` (step name and latency are the caller's).
  virtual bool feed(std::size_t step, std::span<const std::uint8_t> bytes, StepResult& result) = 0;
  // The step timed out: what was seen of it, if anything (e.g. 3 of 4 parameters).
  virtual void timed_out(std::size_t step, StepResult& result) { (void)step, (void)result; }
};

// The client of a byte-stream protocol; nullptr for one without commands
// (native: the project's own stream format has none).
std::unique_ptr<Client> make_client(const std::string& protocol);

}  // namespace imuemu::drivers::handshake
