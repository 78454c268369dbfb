#include "loadgen/trace_cache.h"

#include <cstdint>

#include "loadgen/load_session.h"

namespace catgs::loadgen {

namespace {

// What a trace of `spec` depends on. An orbit is made from the Welcome's bounds, initial pose and
// orbit (every session of one scene gets the same; its session id differs, so not the whole
// message); the other specs from their files, the scene and the size alone.
std::string key_of(const std::string& spec, const GaussianModel* scene, const ::catgs::stream::v1::Welcome& welcome,
                   int width, int height) {
  std::string key = spec + '\n' + std::to_string(width) + 'x' + std::to_string(height) + '\n' +
                    std::to_string(reinterpret_cast<std::uintptr_t>(scene));
  if (spec == "orbit") {
    ::catgs::stream::v1::Welcome view;
    *view.mutable_scene_bounds() = welcome.scene_bounds();
    *view.mutable_initial_pose() = welcome.initial_pose();
    *view.mutable_orbit_centre() = welcome.orbit_centre();
    *view.mutable_up() = welcome.up();
    view.set_scene_scale(welcome.scene_scale());
    view.set_scene_name(welcome.scene_name());
    key += '\n' + view.SerializeAsString();
  }
  return key;
}

}  // namespace

std::shared_ptr<const Trace> TraceCache::get(const std::string& spec, const GaussianModel* scene,
                                             const ::catgs::stream::v1::Welcome& welcome, int width, int height) {
  const std::string key = key_of(spec, scene, welcome, width, height);
  std::promise<std::shared_ptr<const Trace>> promise;
  std::shared_future<std::shared_ptr<const Trace>> made;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    auto it = traces_.find(key);
    if (it != traces_.end())
      made = it->second;
    else
      traces_.emplace(key, promise.get_future().share());
  }
  if (made.valid()) return made.get();  // another session's (waits outside the lock)
  // Made outside the lock: sessions of other traces go on meanwhile.
  try {
    auto trace = std::make_shared<const Trace>(make_load_trace(spec, scene, welcome, width, height));
    promise.set_value(trace);
    return trace;
  } catch (...) {
    promise.set_exception(std::current_exception());
    throw;
  }
}

int TraceCache::made() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return static_cast<int>(traces_.size());
}

}  // namespace catgs::loadgen
