// The scenes a server serves (issue 20, "Scene choice"): every --scene is listed from start-up,
// loaded on first use on a background thread, shared by all its sessions (one host model, and on a
// GPU one device copy per device), and unloaded when no session uses it and a memory budget
// (--scene-memory-mb) needs the room.
//
// Listing before loading (GET /scenes): bounds need every mean, so they are known only once a
// scene has loaded (and stay known after an unload). Everything else comes from peek_scene
// (scene/scene_peek.h): name and format always, Gaussians and SH degree from a PLY header or a
// .splat's size; .spz and glTF list them once loaded. The server loads its first (default) scene
// at start-up (load_now) so that it is listed whole and its first session starts at once.
//
// Sharing: sessions that ask for a scene while it loads join that load; one load, one model, and
// the `prepare` hook's device copies (SceneStore::Options) for all of them. A failed load ends
// only the waits on it (each waiter's ready() gets the error, naming the file and the reason);
// the scene goes back to unloaded, and the next acquire() tries again.
//
// Budget (Options::budget_bytes, 0: none, everything loaded stays): what is counted is each
// loaded model's host bytes (model_bytes) and, while a load runs, the PLY header's estimate of
// it. Before a load starts and after it ends, and whenever a scene's last user leaves, scenes
// with no users are unloaded least recently used first until the loaded bytes fit. A scene with
// users (sessions open on it or waiting for it) is never unloaded; a scene that does not fit even
// alone still loads (the budget bounds what is kept, not what is served), and the log says so.
// Unloading drops the store's model and device copies; their memory is freed when the last
// renderer still holding them (a session that has just ended) is destroyed.
//
// Threads: every member function is thread-safe. Each load runs on a thread of its own (at most
// one per scene at a time). Callbacks run on the loading thread, or, for a scene already loaded,
// inside acquire() on the caller's thread; never with the store's lock held, so they may call
// back into the store. They should only hand the news over (post to a session's strand).
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <ostream>
#include <string>
#include <thread>
#include <vector>

#include "encode/content_rate.h"
#include "forward_model/chunk_bounds.h"
#include "renderer/renderer.h"
#include "scene/gaussian_model.h"
#include "scene/ply_io.h"
#include "scene/scene_peek.h"
#include "process/server_metrics.h"
#include "process/first_view.h"

namespace catgs::server {

// A loaded scene: what sessions render and navigate in. Immutable once published.
struct LoadedScene {
  std::shared_ptr<const GaussianModel> model;
  Bounds bounds;                        // of the means (Welcome.scene_bounds)
  SceneFrame frame;                     // the first view and the frame to navigate in (Welcome)
  std::vector<fm::ChunkBounds> chunks;  // of the model's Gaussians, for the depth probe (pixel_depth.h)
  std::string path;                     // the file it was loaded from
  std::uint64_t bytes = 0;              // model_bytes(*model)
  // Renderers held while the scene is loaded so each GPU keeps one copy of it between sessions
  // (filled by Options::prepare; empty on the CPU renderer).
  std::vector<std::unique_ptr<Renderer>> residents;
  // The scene copies' device bytes held in the GPUs' memory accounting (GpuAssignment::add_scene,
  // one per GPU, or the host slot's with the CPU renderer), given back when the scene unloads.
  std::vector<std::shared_ptr<void>> device_memory_holds;
  // The most device bytes any session's render buffers on this scene grew to (issue 61): a new
  // session's memory estimate starts there (Session::memory_estimate). Changes after publication.
  std::shared_ptr<std::atomic<std::uint64_t>> session_bytes_peak = std::make_shared<std::atomic<std::uint64_t>>(0);
  // The largest buffers any session's renderer on this scene held (Renderer::buffer_shape: slots
  // and list entries; issue 73): a new session reserves them at the door. Change after publication.
  std::shared_ptr<std::atomic<std::uint64_t>> session_gaussians_peak = std::make_shared<std::atomic<std::uint64_t>>(0);
  std::shared_ptr<std::atomic<std::uint64_t>> session_list_peak = std::make_shared<std::atomic<std::uint64_t>>(0);
  // The stream's rate cap by size, probed by the scene's sessions (--bits-per-pixel auto;
  // encode/content_rate.h); the one part that changes after publication (it locks).
  std::shared_ptr<ContentRates> content_rates = std::make_shared<ContentRates>();
};

// Host bytes of a model's arrays (means, scales, rotations, opacities, SH), as loaded.
std::uint64_t model_bytes(const GaussianModel& model);
// The same for a model not yet loaded: `gaussians` of SH degree `sh_degree` (0..3).
std::uint64_t model_bytes(std::uint64_t gaussians, int sh_degree);

class SceneStore {
 public:
  // Reads a scene file: load_scene by default; tests substitute one that blocks or fails. Must
  // call `progress` now and then if it wants progress shown, and let what it throws propagate.
  using Loader = std::function<GaussianModel(const std::string& path, const LoadProgress& progress)>;
  // Called on the loading thread once the model, bounds and frame are set, before the scene is
  // published (the server uploads the device copies here). What it throws fails the load.
  using Prepare = std::function<void(LoadedScene& scene)>;
  // While a scene loads: percent 0..100, Gaussians read and in the file (0 and 0 when the format
  // reports nothing). A waiter sees percent rise; 100 comes once, just before ready().
  using Progress = std::function<void(int percent, std::uint64_t done, std::uint64_t total)>;
  // The load ended: the scene (error empty), or null and `error` ("PATH: reason").
  using Ready = std::function<void(std::shared_ptr<const LoadedScene> scene, const std::string& error)>;

  struct Source {
    std::string path;
    std::string cameras;  // --cameras for this scene ("": look beside it; first_view.h)
  };
  struct Options {
    std::uint64_t budget_bytes = 0;    // --scene-memory-mb x 2^20; 0: no budget
    Loader loader;                     // empty: load_scene
    Prepare prepare;                   // empty: nothing
    ServerMetrics* metrics = nullptr;  // scene gauges and counters (may be null)
    std::ostream* log = nullptr;       // "scene: ..." lines (may be null)
  };

  // A use of one scene: while it exists the scene is not unloaded. Destroying it before the load
  // ended withdraws the wait (its callbacks are dropped, not called).
  class Use {
   public:
    ~Use();
    Use(const Use&) = delete;
    Use& operator=(const Use&) = delete;
    std::size_t index() const { return index_; }

   private:
    friend class SceneStore;
    Use(SceneStore& store, std::size_t index, std::uint64_t id) : store_(store), index_(index), id_(id) {}
    SceneStore& store_;
    std::size_t index_;
    std::uint64_t id_;
  };

  // Lists `sources` from their headers (peek_scene); loads nothing. A header that cannot be read
  // is logged as a warning and the scene is still listed (by name, file and format "unknown"): its
  // first use then fails with the loader's error. Throws std::runtime_error when two sources have
  // one name (naming both files: Hello picks scenes by name) or there are none.
  SceneStore(std::vector<Source> sources, Options options);
  // stop().
  ~SceneStore();
  // Cancels loads in progress (at their next progress call; their waiters get an error) and
  // waits for their threads; later acquires of an unloaded scene wait for ever (the server calls
  // it while stopping, before its pools: waiters' callbacks post to them).
  void stop();
  SceneStore(const SceneStore&) = delete;
  SceneStore& operator=(const SceneStore&) = delete;

  std::size_t size() const { return slots_.size(); }
  // The index of the scene named `name` ("": the first), or nullopt.
  std::optional<std::size_t> find(const std::string& name) const;
  // The name of scene `index` (< size()).
  const std::string& name(std::size_t index) const { return slots_.at(index).peek.name; }
  // "a, b, c": every name, in --scene order (for errors).
  std::string names() const;
  // GET /scenes: [{"name", "file", "format", "gaussians", "sh_degree", "bounds": {"min": [x, y, z],
  // "max": [...]}, "loaded"}] in --scene order (the first is the default), as JSON; unknown
  // values are null (see the top of this file).
  std::string json() const;

  // Loads scene `index` on this thread now, unless it is loaded (start-up: the default scene).
  // Throws what the loader and prepare throw (std::runtime_error, SceneFileError naming the file).
  void load_now(std::size_t index);
  // Takes a use of scene `index` (< size()) and calls ready() once it is loaded: at once, inside
  // this call, when it already is; else after the load it joins or starts (on a new thread, after
  // unloading unused scenes for the budget). progress() is called while it loads (see Progress).
  std::unique_ptr<Use> acquire(std::size_t index, Progress progress, Ready ready);

  // The loaded scene at `index`, or null (tests, logs).
  std::shared_ptr<const LoadedScene> loaded(std::size_t index) const;
  // Scene loads started so far, on a thread or by load_now (tests: one load for many sessions).
  std::uint64_t loads_started() const;

 private:
  enum class State { unloaded, loading, loaded };
  struct Waiter {
    std::uint64_t id;
    Progress progress;
    Ready ready;
  };
  struct Slot {
    Source source;
    ScenePeek peek;
    std::optional<Bounds> bounds;  // known once loaded
    State state = State::unloaded;
    std::shared_ptr<const LoadedScene> scene;  // loaded
    std::uint64_t reserved = 0;                // loading: the header's estimate of its bytes
    int users = 0;                             // Uses held
    std::uint64_t last_used = 0;               // tick of the last acquire or release
    int percent = 0;                           // loading: the last percent sent
    std::uint64_t done = 0, total = 0;         // loading: Gaussians read, in the file
    std::vector<Waiter> waiters;               // loading
  };
  struct Worker {
    std::thread thread;
    std::shared_ptr<std::atomic<bool>> done;
  };

  // Runs the load of slot `index` (on whichever thread calls it) and publishes the outcome.
  void run_load(std::size_t index);
  std::shared_ptr<LoadedScene> read_scene(std::size_t index);  // loader, bounds, frame, prepare
  void report(std::size_t index, std::uint64_t done, std::uint64_t total);
  // The load of slot `index` ended: the scene (error empty) or the error; tells its waiters.
  void publish(std::size_t index, std::shared_ptr<const LoadedScene> scene, const std::string& error);
  void release(std::size_t index, std::uint64_t id);
  // Unloads unused loaded scenes, least recently used first, until the loaded and reserved bytes
  // plus `incoming` fit the budget (or nothing unused is left); `keep` is never unloaded. Returns
  // the unloaded scenes, to be destroyed outside the lock. Lock held.
  std::vector<std::shared_ptr<const LoadedScene>> evict(std::uint64_t incoming, std::size_t keep);
  std::uint64_t held_bytes() const;  // loaded + reserved; lock held
  void publish_gauges() const;       // lock held
  void reap();                       // joins finished load threads (outside the lock)
  void say(const std::string& line) const;

  const Options options_;
  mutable std::mutex mutex_;
  std::vector<Slot> slots_;
  std::uint64_t tick_ = 0;
  std::uint64_t next_id_ = 1;
  std::uint64_t loads_started_ = 0;
  std::vector<Worker> workers_;
  std::atomic<bool> stopping_{false};
  mutable std::mutex log_mutex_;
};

}  // namespace catgs::server
