// From a parsed scene (daemon/scene/scene_config.hpp) to a running emission engine
// (daemon/engine/emission.hpp): the poses (file, built-in sample or live source),
// one device per [[imu]] with its smoothing options, mounting, encoder,
// transport and sync output. What imuemud runs, and what
// `imuemu generate --scene` reproduces in batch for comparison.
#pragma once

#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "core/trajectory.hpp"
#include "daemon/engine/emission.hpp"
#include "daemon/scene/scene_config.hpp"
#include "io/pose_source.hpp"

namespace imuemu::io {
class PoseSource;
}

namespace imuemu::scene {

// A device of the scene could not be opened (missing serial port, CAN
// interface, GPIO chip or line, pty link directory): names the device.
class DeviceOpenError : public std::runtime_error {
 public:
  DeviceOpenError(std::string imu, const std::string& what)
      : std::runtime_error("imu '" + imu + "': " + what), imu_(std::move(imu)) {}
  const std::string& imu() const noexcept { return imu_; }

 private:
  std::string imu_;
};

struct RunnerOptions {
  std::function<void(std::string_view)> log;  // transports' and sources' log lines
  // Non-empty: publish every pty link in this directory (same file name)
  // instead of where the scene says (tests and unprivileged runs).
  std::string pty_link_dir;
  // Set: overrides the scene's [daemon] late_ticks (true: drop).
  std::optional<bool> drop_late_ticks;
};

// The body poses of a file or built-in sample trajectory in the scene's
// physics, once (no looping). Throws io::CsvFormatError for a bad file,
// std::invalid_argument for a live source.
std::vector<Pose> scene_trajectory(const SceneConfig& scene);

// With [trajectory] loop = true: the trajectory followed by further copies,
// each shifted in time by its span plus a gap beyond max_gap_s (so the
// pipeline splits there: one-sided windows, no smoothing across the jump back
// to the start, a silent gap on the wire), up to at least min_span_ns, but
// at most limits::kMaxLoopKnots knots in all and only copies whose times fit
// int64 ns (the run then restarts sooner).
std::vector<Pose> looped(const std::vector<Pose>& once, const SceneConfig& scene, TimeNs min_span_ns);

// The span loop = true covers before the daemon restarts the run.
inline constexpr TimeNs kLoopSpanNs = 24LL * 3600 * kNsPerSecond;

// A pty link as published: the scene's, or moved into options.pty_link_dir.
std::string pty_link_path(const ImuConfig& imu, const RunnerOptions& options);

// The live pose source's options a scene asks for (physics, the gap limit a
// re-acquired stream is placed beyond, the MAVLink vehicle, the log).
io::PoseSourceOptions pose_source_options(const SceneConfig& scene, const RunnerOptions& options);

struct BuiltEngine {
  std::unique_ptr<io::PoseSource> source;  // live input (declared first: outlives the engine)
  std::unique_ptr<emission::EmissionEngine> engine;
  std::vector<std::string> outputs;        // per device: "imu0: native -> pty /dev/pts/3 (/run/imuemu/ttyIMU0)"
};

// Transports kept open across a reload, by reuse_key(): a new scene whose
// device has the same key takes the open one (a pty's reader is not hung up).
using ReusableTransports = std::map<std::string, std::unique_ptr<drivers::Transport>>;

// What identifies an open transport for reuse: a pty's published link, queue
// and slave mode; empty for the others (reopened at every start).
std::string reuse_key(const ImuConfig& imu, const RunnerOptions& options);

// Opens every device (throws DeviceOpenError naming the first that fails) and
// builds the engine, not started. A device whose reuse_key() is in `reuse`
// takes that transport (moved out of the map).
BuiltEngine build_engine(const SceneConfig& scene, const RunnerOptions& options, ReusableTransports* reuse = nullptr);

}  // namespace imuemu::scene
