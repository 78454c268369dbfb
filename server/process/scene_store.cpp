#include "process/scene_store.h"

#include "forward_model/chunk_bounds.h"

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <limits>
#include <sstream>
#include <stdexcept>

#include <nlohmann/json.hpp>

namespace catgs::server {

namespace {

using Clock = std::chrono::steady_clock;

double ms_since(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

std::string mib(std::uint64_t bytes) {
  std::ostringstream o;
  o.precision(1);
  o << std::fixed << static_cast<double>(bytes) / (1 << 20) << " MiB";
  return o.str();
}

constexpr std::size_t kNone = std::numeric_limits<std::size_t>::max();

}  // namespace

std::uint64_t model_bytes(std::uint64_t gaussians, int sh_degree) {
  // means 3 + log_scales 3 + rotations 4 + opacity 1 + SH K x 3 floats a Gaussian.
  return gaussians * (11 + 3 * static_cast<std::uint64_t>(sh_coeff_count(sh_degree))) * sizeof(float);
}

std::uint64_t model_bytes(const GaussianModel& m) {
  return (m.means.size() + m.log_scales.size() + m.rotations.size() + m.opacity_logits.size() + m.sh.size()) *
         sizeof(float);
}

SceneStore::Use::~Use() { store_.release(index_, id_); }

SceneStore::SceneStore(std::vector<Source> sources, Options options) : options_(std::move(options)) {
  if (sources.empty()) throw std::runtime_error("no --scene to serve");
  slots_.resize(sources.size());
  for (std::size_t i = 0; i < sources.size(); ++i) {
    Slot& s = slots_[i];
    s.source = std::move(sources[i]);
    try {
      s.peek = peek_scene(s.source.path);
    } catch (const std::exception& e) {
      say(std::string("scene: warning: ") + e.what() + " (listed; its first use will try to load it)");
      s.peek.name = scene_name(s.source.path);
      s.peek.format = "unknown";
    }
    for (std::size_t j = 0; j < i; ++j)
      if (slots_[j].peek.name == s.peek.name)
        throw std::runtime_error("--scene " + s.source.path + ": a scene named '" + s.peek.name +
                                 "' is already served (" + slots_[j].source.path + "); Hello picks scenes by name");
  }
  publish_gauges();
}

SceneStore::~SceneStore() { stop(); }

void SceneStore::stop() {
  stopping_ = true;
  std::vector<Worker> workers;
  {
    const std::lock_guard<std::mutex> lock(mutex_);
    workers.swap(workers_);
  }
  for (Worker& w : workers) w.thread.join();
}

std::optional<std::size_t> SceneStore::find(const std::string& name) const {
  if (name.empty()) return 0;
  for (std::size_t i = 0; i < slots_.size(); ++i)  // names are fixed at construction
    if (slots_[i].peek.name == name) return i;
  return std::nullopt;
}

std::string SceneStore::names() const {
  std::string out;
  for (const Slot& s : slots_) out += (out.empty() ? "" : ", ") + s.peek.name;
  return out;
}

std::string SceneStore::json() const {
  const std::lock_guard<std::mutex> lock(mutex_);
  nlohmann::json out = nlohmann::json::array();
  for (const Slot& s : slots_) {
    nlohmann::json j = {{"name", s.peek.name},
                        {"file", std::filesystem::path(s.source.path).filename().string()},
                        {"format", s.peek.format},
                        {"gaussians", nullptr},
                        {"sh_degree", nullptr},
                        {"bounds", nullptr},
                        {"loaded", s.state == State::loaded}};
    if (s.peek.gaussians) j["gaussians"] = *s.peek.gaussians;
    if (s.peek.sh_degree) j["sh_degree"] = *s.peek.sh_degree;
    if (s.bounds)
      j["bounds"] = {{"min", {s.bounds->min.x, s.bounds->min.y, s.bounds->min.z}},
                     {"max", {s.bounds->max.x, s.bounds->max.y, s.bounds->max.z}}};
    out.push_back(std::move(j));
  }
  return out.dump() + "\n";
}

std::shared_ptr<const LoadedScene> SceneStore::loaded(std::size_t index) const {
  const std::lock_guard<std::mutex> lock(mutex_);
  return slots_.at(index).scene;
}

std::uint64_t SceneStore::loads_started() const {
  const std::lock_guard<std::mutex> lock(mutex_);
  return loads_started_;
}

void SceneStore::load_now(std::size_t index) {
  std::vector<std::shared_ptr<const LoadedScene>> evicted;
  {
    const std::lock_guard<std::mutex> lock(mutex_);
    Slot& s = slots_.at(index);
    if (s.state == State::loaded) return;
    if (s.state == State::loading) throw std::logic_error("load_now: " + s.source.path + " is already loading");
    s.state = State::loading;
    s.percent = 0;
    s.reserved = s.peek.gaussians && s.peek.sh_degree ? model_bytes(*s.peek.gaussians, *s.peek.sh_degree) : 0;
    evicted = evict(0, index);  // the reservation is counted
    loads_started_++;
  }
  evicted.clear();
  std::shared_ptr<LoadedScene> scene;
  try {
    scene = read_scene(index);
  } catch (const std::exception& e) {
    publish(index, nullptr, e.what());
    throw;
  }
  publish(index, std::move(scene), "");
}

std::unique_ptr<SceneStore::Use> SceneStore::acquire(std::size_t index, Progress progress, Ready ready) {
  reap();
  std::shared_ptr<const LoadedScene> now;
  std::vector<std::shared_ptr<const LoadedScene>> evicted;
  bool start = false;
  int percent = 0;
  std::uint64_t done = 0, total = 0;
  std::unique_ptr<Use> use;
  {
    const std::lock_guard<std::mutex> lock(mutex_);
    Slot& s = slots_.at(index);
    use.reset(new Use(*this, index, next_id_++));
    s.users++;
    s.last_used = ++tick_;
    if (s.state == State::loaded) {
      now = s.scene;
    } else {
      s.waiters.push_back({use->id_, progress, std::move(ready)});
      if (s.state == State::unloaded && !stopping_) {
        s.state = State::loading;
        s.percent = 0;
        s.done = 0;
        s.total = s.peek.gaussians.value_or(0);
        s.reserved = s.peek.gaussians && s.peek.sh_degree ? model_bytes(*s.peek.gaussians, *s.peek.sh_degree) : 0;
        evicted = evict(0, index);  // the reservation is counted
        loads_started_++;
        start = true;
      }
      percent = s.percent;
      done = s.done;
      total = s.total;
    }
  }
  evicted.clear();  // the unloaded scenes' memory goes back here, outside the lock
  if (now) {
    ready(now, "");
    return use;
  }
  if (progress) progress(percent, done, total);
  if (start) {
    auto finished = std::make_shared<std::atomic<bool>>(false);
    std::thread thread([this, index, finished] {
      run_load(index);
      *finished = true;
    });
    const std::lock_guard<std::mutex> lock(mutex_);
    workers_.push_back({std::move(thread), std::move(finished)});
  }
  return use;
}

void SceneStore::release(std::size_t index, std::uint64_t id) {
  std::vector<std::shared_ptr<const LoadedScene>> evicted;
  std::vector<Waiter> withdrawn;  // their callbacks (and what they hold) die outside the lock
  {
    const std::lock_guard<std::mutex> lock(mutex_);
    Slot& s = slots_[index];
    s.users--;
    s.last_used = ++tick_;
    for (auto it = s.waiters.begin(); it != s.waiters.end(); ++it)
      if (it->id == id) {
        withdrawn.push_back(std::move(*it));
        s.waiters.erase(it);
        break;
      }
    // The last user left a scene kept over the budget (it was in use when others loaded).
    if (s.users == 0) evicted = evict(0, kNone);
    publish_gauges();
  }
}

void SceneStore::run_load(std::size_t index) {
  std::shared_ptr<LoadedScene> scene;
  std::string error;
  try {
    scene = read_scene(index);
  } catch (const std::exception& e) {
    error = e.what();
  }
  publish(index, std::move(scene), error);
}

std::shared_ptr<LoadedScene> SceneStore::read_scene(std::size_t index) {
  const Source& source = slots_[index].source;  // fixed at construction
  const std::string& name = slots_[index].peek.name;
  const auto t0 = Clock::now();
  say("scene: loading " + source.path + " (" + name + ")");
  const LoadProgress progress = [this, index](std::uint64_t done, std::uint64_t total) { report(index, done, total); };
  GaussianModel model = options_.loader ? options_.loader(source.path, progress) : load_scene(source.path, progress);
  // Every step until the first frame can be drawn counts (issue 46): each is timed in the log line.
  const double read_ms = ms_since(t0);
  auto t = Clock::now();
  const auto lap = [&t] {
    const double ms = ms_since(t);
    t = Clock::now();
    return ms;
  };
  model.name = name;
  auto scene = std::make_shared<LoadedScene>();
  scene->model = std::make_shared<const GaussianModel>(std::move(model));
  scene->path = source.path;
  scene->bounds = scene->model->bounds();
  scene->chunks = chunk_bounds_of(*scene->model);  // the depth probe's culling (DepthRequest)
  scene->bytes = model_bytes(*scene->model);
  const double bounds_ms = lap();
  // A bad --cameras file fails the load (at start-up: the start); a bad discovered one only warns.
  std::ostringstream frame_log;
  scene->frame = choose_scene_frame(*scene->model, source.path, source.cameras, frame_log);
  const double frame_ms = lap();
  if (options_.prepare) options_.prepare(*scene);
  const double prepare_ms = lap();
  std::ostringstream line;
  line << "scene: " << source.path << " (" << name << "), " << scene->model->size() << " Gaussians, SH degree "
       << scene->model->sh_degree << ", " << mib(scene->bytes) << ", loaded in " << ms_since(t0) << " ms (read "
       << read_ms << ", bounds " << bounds_ms << ", first view " << frame_ms << ", device copies " << prepare_ms
       << ")\n"
       << frame_log.str();
  std::string text = line.str();
  if (!text.empty() && text.back() == '\n') text.pop_back();
  say(text);
  return scene;
}

void SceneStore::report(std::size_t index, std::uint64_t done, std::uint64_t total) {
  // Thrown through the loader: a stopping server does not wait for a long load to end.
  if (stopping_) throw std::runtime_error("load cancelled: the server is stopping");
  // 100 is kept for the end: the frame and the device copies come after the last row.
  const int percent = total == 0 ? 0 : static_cast<int>(std::min<std::uint64_t>(99, done * 100 / total));
  std::vector<Progress> tell;
  int before = 0;
  {
    const std::lock_guard<std::mutex> lock(mutex_);
    Slot& s = slots_[index];
    s.done = done;
    s.total = total;
    if (percent <= s.percent) return;
    before = s.percent;
    s.percent = percent;
    for (const Waiter& w : s.waiters)
      if (w.progress) tell.push_back(w.progress);
  }
  // A line each time a quarter is passed: reports come every few thousand Gaussians, so the
  // percentages jump (38 k Gaussians: 21, 42, 64, 85) and seldom land on 25, 50 or 75.
  if (percent / 25 > before / 25)
    say("scene: loading " + slots_[index].source.path + ": " + std::to_string(done) + " of " + std::to_string(total) +
        " Gaussians (" + std::to_string(percent) + "%)");
  for (const Progress& p : tell) p(percent, done, total);
}

void SceneStore::publish(std::size_t index, std::shared_ptr<const LoadedScene> scene, const std::string& error) {
  std::vector<Waiter> waiters;
  std::vector<std::shared_ptr<const LoadedScene>> evicted;
  std::string over;
  {
    const std::lock_guard<std::mutex> lock(mutex_);
    Slot& s = slots_[index];
    s.reserved = 0;
    waiters.swap(s.waiters);
    if (scene) {
      s.state = State::loaded;
      s.scene = scene;
      s.bounds = scene->bounds;
      s.peek.gaussians = scene->model->size();
      s.peek.sh_degree = scene->model->sh_degree;
      if (options_.metrics) options_.metrics->scene_loads_total++;
      evicted = evict(0, index);
      if (options_.budget_bytes && held_bytes() > options_.budget_bytes)
        over = "scene: " + mib(held_bytes()) + " of scenes loaded, over --scene-memory-mb (" +
               mib(options_.budget_bytes) + "): the others in memory are in use";
    } else {
      s.state = State::unloaded;
      s.percent = 0;
      if (options_.metrics) options_.metrics->scene_load_failures_total++;
    }
    publish_gauges();
  }
  evicted.clear();
  if (!over.empty()) say(over);
  if (!scene) say("scene: load failed: " + error);
  for (Waiter& w : waiters) {
    if (!scene) {
      w.ready(nullptr, error);
      continue;
    }
    const std::uint64_t n = scene->model->size();
    if (w.progress) w.progress(100, n, n);
    w.ready(scene, "");
  }
}

std::vector<std::shared_ptr<const LoadedScene>> SceneStore::evict(std::uint64_t incoming, std::size_t keep) {
  std::vector<std::shared_ptr<const LoadedScene>> out;
  if (options_.budget_bytes == 0) return out;
  while (held_bytes() + incoming > options_.budget_bytes) {
    std::size_t lru = kNone;
    for (std::size_t i = 0; i < slots_.size(); ++i) {
      const Slot& s = slots_[i];
      if (i == keep || s.state != State::loaded || s.users > 0) continue;
      if (lru == kNone || s.last_used < slots_[lru].last_used) lru = i;
    }
    if (lru == kNone) break;  // everything left is in use (or is the scene being loaded)
    Slot& s = slots_[lru];
    say("scene: unloaded " + s.peek.name + " (" + mib(s.scene->bytes) + ", unused) for --scene-memory-mb " +
        mib(options_.budget_bytes));
    out.push_back(std::move(s.scene));
    s.scene.reset();
    s.state = State::unloaded;
    s.percent = 0;
    if (options_.metrics) options_.metrics->scene_unloads_total++;
  }
  return out;
}

std::uint64_t SceneStore::held_bytes() const {
  std::uint64_t bytes = 0;
  for (const Slot& s : slots_) bytes += (s.scene ? s.scene->bytes : 0) + s.reserved;
  return bytes;
}

void SceneStore::publish_gauges() const {
  if (!options_.metrics) return;
  std::int64_t n = 0, bytes = 0;
  for (const Slot& s : slots_)
    if (s.scene) {
      n++;
      bytes += static_cast<std::int64_t>(s.scene->bytes);
    }
  options_.metrics->scenes_loaded = n;
  options_.metrics->scene_bytes = bytes;
}

void SceneStore::reap() {
  std::vector<Worker> finished;
  {
    const std::lock_guard<std::mutex> lock(mutex_);
    const auto split =
        std::stable_partition(workers_.begin(), workers_.end(), [](const Worker& w) { return !*w.done; });
    std::move(split, workers_.end(), std::back_inserter(finished));
    workers_.erase(split, workers_.end());
  }
  for (Worker& w : finished) w.thread.join();  // already past run_load: returns at once
}

void SceneStore::say(const std::string& line) const {
  if (!options_.log) return;
  const std::lock_guard<std::mutex> lock(log_mutex_);
  *options_.log << line << std::endl;
}

}  // namespace catgs::server
