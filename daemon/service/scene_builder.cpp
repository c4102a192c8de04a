#include "daemon/service/scene_builder.hpp"

#include <stdexcept>
#include <utility>

#include <boost/asio/post.hpp>

#include "daemon/engine/emission.hpp"
#include "daemon/scene/default_scene.hpp"
#include "daemon/scene/scene_check.hpp"
#include "io/pose_source.hpp"

namespace imuemu::service {

void run_scene_build_job(SceneBuildJob& job) {
  if (job.kind == SceneBuildJob::Kind::start) {
    job.built = scene::build_engine(job.scene, job.runner, &job.reuse);
    return;
  }
  scene::SceneConfig next = job.scene_path.empty() ? scene::default_scene() : scene::parse_scene_file(job.scene_path);
  const scene::SceneCheck check = scene::check_scene(next);
  if (check.refused) throw std::runtime_error(scene::refusal_text(check) + ":\n" + scene::to_text(check));
  const bool live = scene::is_live(next.trajectory.kind);
  if (!live) {
    // The trajectory's content (a file that became malformed) is what most
    // often fails a reload: found here, while the old scene still runs.
    const std::size_t poses = scene::scene_trajectory(next).size();
    if (poses < 2)
      throw std::runtime_error(next.file + ": the trajectory has " + std::to_string(poses) +
                               " poses; at least two are needed");
  }
  job.scene = std::move(next);
}

void SceneBuilder::launch(std::shared_ptr<SceneBuildJob> job) {
  if (thread_.joinable()) thread_.join();
  job->started_ns = emission::monotonic_now_ns();
  job_ = job;
  thread_ = std::thread([this, job] {
    try {
      run_scene_build_job(*job);
    } catch (...) {  // nothing leaves the worker: the io thread reports it
      job->error = std::current_exception();
    }
    try {
      boost::asio::post(io_, [this, job] { done_(job); });
    } catch (...) {  // no memory for the handler: the build is lost, the daemon stops
      job->error = std::current_exception();
    }
    job->done.store(true, std::memory_order_release);
  });
}

bool SceneBuilder::join(std::chrono::milliseconds limit) {
  if (!thread_.joinable()) return true;
  const auto until = std::chrono::steady_clock::now() + limit;
  while (!(job_ && job_->done.load(std::memory_order_acquire))) {
    if (std::chrono::steady_clock::now() >= until) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  thread_.join();
  job_.reset();
  return true;
}

}  // namespace imuemu::service
