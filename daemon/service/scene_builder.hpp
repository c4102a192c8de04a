// Building a scene off imuemud's io thread (issue 13 H3/H4). Building can
// take seconds (a long sample trajectory, a 200 MB file) or never end (a
// scene whose derived sizes are absurd): on the service io thread it blocked
// SIGTERM, the control socket and the watchdog. So one worker thread at a
// time runs one SceneBuildJob and posts it back to the io thread when it
// ends; the io thread only launches a job and takes its result, nothing else
// is shared. Two kinds of job:
//   start:    scene::build_engine (opens the devices; not started)
//   validate: re-read the scene file, check it and compute its trajectory,
//             for a reload: the running scene is stopped only if this works.
// What the daemon does with the result is daemon/service/scene_lifecycle.hpp.
#pragma once

#include <atomic>
#include <chrono>
#include <exception>
#include <functional>
#include <memory>
#include <string>
#include <thread>

#include <boost/asio/io_context.hpp>

#include "core/types.hpp"
#include "daemon/scene/scene_config.hpp"
#include "daemon/scene/scene_runner.hpp"

namespace imuemu::service {

struct SceneBuildJob {
  enum class Kind { start, validate };
  Kind kind = Kind::start;
  scene::SceneConfig scene;        // start: the scene to build; validate: the re-read one
  std::string scene_path;          // validate: empty for the built-in scene
  scene::RunnerOptions runner;     // start (a copy: the worker shares nothing)
  TimeNs next_retry_ns = 0;        // start: back-off after this attempt (device_missing = "wait")
  scene::ReusableTransports reuse;  // start: transports kept open from the previous engine (ptys across a reload)
  scene::BuiltEngine built;        // start: the result
  std::exception_ptr error;        // what the build threw
  TimeNs started_ns = 0;           // CLOCK_MONOTONIC, set at launch
  std::atomic<bool> done{false};   // the worker has posted its result and ends
};

// The job's work, on the worker: throws what the build or the checks throw
// (a validate job: also a link loaded beyond 100 %, a trajectory of fewer
// than two poses).
void run_scene_build_job(SceneBuildJob& job);

// The worker thread. No exception leaves it: what the job throws goes to
// job.error, and the result is posted to `done` on the io thread.
class SceneBuilder {
 public:
  using Done = std::function<void(const std::shared_ptr<SceneBuildJob>& job)>;

  SceneBuilder(boost::asio::io_context& io, Done done) : io_(io), done_(std::move(done)) {}
  // The worker must have been joined (join() returned true) or never launched.
  ~SceneBuilder() = default;
  SceneBuilder(const SceneBuilder&) = delete;
  SceneBuilder& operator=(const SceneBuilder&) = delete;

  // On the io thread: stamps job->started_ns and runs the job on a new
  // worker (the previous worker posted its result before ending: joining it
  // first is brief).
  void launch(std::shared_ptr<SceneBuildJob> job);

  // After io.run() returned: waits (bounded) for a worker still building.
  // False if it did not end in time: the caller must not destroy what the
  // worker may still post to (it exits the process instead).
  bool join(std::chrono::milliseconds limit);

 private:
  boost::asio::io_context& io_;
  Done done_;
  std::thread thread_;
  std::shared_ptr<SceneBuildJob> job_;  // the job of thread_ (for join)
};

}  // namespace imuemu::service
