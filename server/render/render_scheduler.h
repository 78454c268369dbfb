// The render scheduler: the render lanes every session's renders share, taken by sessions in turn
// (docs/DESIGN.md "Server").
//
// Sessions post their render jobs here under their own key (the connection id); a fixed number of
// "render lanes" (threads) run them. Fairness is per session, not per request: the lanes serve
// the sessions with queued jobs in rounds, one job per session per round (a session re-enters at
// the back of the round after each job), so a session that posts many or large jobs cannot push
// the others' frames back by more than one of its jobs. A render waiting for its turn holds no
// worker thread (strands, encodes and timers keep running on the pool meanwhile).
//
// Pixels in flight: each job declares its pixel count (width x height). A job starts only while
// the pixels of the jobs running plus its own stay within the server-wide cap
// (--max-pixels-in-flight), so memory that scales with frame size (render lists, image buffers)
// stays bounded however many large-frame sessions connect; a job larger than the cap still runs,
// alone. The next session in turn waits for room rather than being overtaken by smaller jobs, so
// a large frame cannot starve.
//
// Background jobs (post_background: the frames of a video export, session/video_export.h) run at
// a lower priority: a lane takes one only when no session's job is queued, within the same pixel
// cap, never on the last free lane when there are several (one lane stays for live work), and,
// for up to the background yield (--export-yield-ms, 1 s by default), only while no session's job
// is running either: an export frame beside a live one shares the GPU (or, with the CPU core,
// every core) with it and slows it down (RESULTS.md, "Video export"). An export posts its next
// frame only when the previous one is done, so between any two of its frames every live job
// queued meanwhile goes first: a live frame waits at most for one export frame already running,
// and not at all while another lane is free. On a saturated server an export gets about one
// frame per yield.
//
// Frames in flight (--frames-per-lane, default_frames_per_lane): a job may return a Finish, its
// second half: the frame it queued on the GPU (Renderer::begin_yuv420_at), to be waited for and
// handed on (Renderer::finish_yuv420). The lane keeps up to frames_per_lane such frames begun and
// takes the next session's job while the GPU draws them, so a lane no longer holds the GPU idle
// for the frame's length while the host waits for its planes; it runs the oldest finish when it
// holds that many, when no job may start, or first thing when that frame is ready already
// (Finish::ready: a frame done on the GPU does not wait behind the next one's begin). A job
// counts as running (the pixel cap, drain(), background jobs' gaps) until its finish has run. A session's next job is posted only after its
// frame's finish, so a renderer never has two frames begun. 1: each frame is finished before the
// lane takes another (the CPU core's default: its begin draws the whole frame).
//
// Lane count (default_lanes): --render-lanes when given; otherwise 4 with the CUDA renderer (a
// few renders in flight share one GPU) and --threads with the CPU renderer (a CPU render is CPU
// work like the pool's, so it gets as many threads).
//
// Threads: post() is thread-safe (sessions post from their strands). start(), drain(), stop() and
// poll() belong to the thread that owns the server (start-up and shutdown), in that order.
#pragma once

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <type_traits>
#include <utility>
#include <vector>

namespace catgs::server {

namespace detail {
// A move-only callable returning R, behind one virtual call: the scheduler's jobs (R = its
// Finish: a job returning void returns an empty one) and their finishes (R = void).
template <class R>
struct Callable {
  virtual ~Callable() = default;
  virtual R run() = 0;
};
template <class R, class F>
struct CallableOf final : Callable<R> {
  explicit CallableOf(F&& f) : fn(std::move(f)) {}
  explicit CallableOf(const F& f) : fn(f) {}
  R run() override {
    if constexpr (std::is_void_v<R> || !std::is_void_v<std::invoke_result_t<F&>>) {
      return fn();
    } else {
      fn();
      return R{};
    }
  }
  F fn;
};
}  // namespace detail

class RenderScheduler {
 public:
  using Owner = std::uint64_t;  // whose job: a session's connection id

  RenderScheduler() = default;
  // Stops and joins lanes still running (a server that never reached its orderly shutdown); jobs
  // still queued are destroyed without running.
  ~RenderScheduler();
  RenderScheduler(const RenderScheduler&) = delete;
  RenderScheduler& operator=(const RenderScheduler&) = delete;

  // The lane count for `requested` (RenderSettings::render_lanes; > 0 wins), the resolved
  // `renderer_kind` ("cpu" or "cuda") and the worker count `threads`.
  static int default_lanes(int requested, const std::string& renderer_kind, int threads);
  // Frames a lane keeps begun (see above) for `requested` (RenderSettings::frames_per_lane; > 0
  // wins) and the resolved `renderer_kind`: 2 with the CUDA renderer, 1 with the CPU one.
  static int default_frames_per_lane(int requested, const std::string& renderer_kind);
  // Set before start() (>= 1).
  void set_frames_per_lane(int frames) { frames_per_lane_ = std::max(1, frames); }
  int frames_per_lane() const { return frames_per_lane_; }

  // A job's second half (see "Frames in flight"): a move-only void() callable, or empty, and
  // optionally `ready`, a bool() that says without waiting whether the callable would run without
  // waiting (the frame's planes are done); a lane finishes a ready frame before it begins another.
  // Without `ready` a frame counts as not ready. Neither may throw (a throw is logged; a `ready`
  // that throws counts as ready, so that the finish meets the error).
  class Finish {
   public:
    Finish() = default;
    template <class F>
    static Finish of(F&& f, std::function<bool()> ready = {}) {
      Finish out;
      out.fn_ = std::make_unique<detail::CallableOf<void, std::decay_t<F>>>(std::forward<F>(f));
      out.ready_ = std::move(ready);
      return out;
    }
    explicit operator bool() const { return fn_ != nullptr; }
    void operator()() { fn_->run(); }
    bool ready() const {
      if (!ready_) return false;
      try {
        return ready_();
      } catch (...) {
        return true;
      }
    }

   private:
    std::unique_ptr<detail::Callable<void>> fn_;
    std::function<bool()> ready_;
  };

  // How long a background job waits for a moment when no live job runs (default 1000 ms; set
  // before start()). 0: it waits only for queued live jobs.
  void set_background_yield(std::chrono::milliseconds yield) { background_yield_ = yield; }

  // Starts `lanes` (>= 1) lane threads with a cap of `max_pixels_in_flight` (> 0) pixels rendering
  // at once. Jobs posted before start() wait in their queues.
  void start(int lanes, std::int64_t max_pixels_in_flight);
  // Lanes started.
  int lanes() const { return static_cast<int>(lanes_.size()); }
  // The lane (0 .. lanes() - 1) running the calling thread's job, for the frame's timings
  // (FrameTimings.render_lane); -1 outside a lane (poll() after stop(), another thread).
  static int current_lane();

  // Thread-safe. Queues `job` (a callable returning void or a Finish, move-only allowed) of
  // `pixels` pixels behind `owner`'s earlier jobs; a lane runs it in `owner`'s turn. A job must not
  // throw (a throw is logged and the job counts as done).
  template <class Job>
  void post(Owner owner, std::int64_t pixels, Job&& job) {
    enqueue(owner, pixels, std::make_unique<Task<std::decay_t<Job>>>(std::forward<Job>(job)));
  }

  // Thread-safe. Queues a background job (see above), FIFO among background jobs; `owner` is for
  // logs and metrics only.
  template <class Job>
  void post_background(Owner owner, std::int64_t pixels, Job&& job) {
    enqueue_background(owner, pixels, std::make_unique<Task<std::decay_t<Job>>>(std::forward<Job>(job)));
  }

  // Thread-safe: jobs queued (not running) and pixels of the jobs running, for metrics and tests.
  std::size_t queued() const;
  std::int64_t pixels_in_flight() const;

  // Shutdown, step 1: no more work is expected (sessions are closed); waits until the lanes
  // have run every queued job or `deadline` passes. Returns true when the queues ran dry.
  bool drain(std::chrono::steady_clock::time_point deadline);
  // Step 2: stops the lanes (a job in progress finishes; queued ones stay queued) and joins them.
  void stop();
  // Step 3, after stop(): runs the jobs left queued (past drain's deadline) on the calling
  // thread, without waiting for more. Returns how many ran.
  std::size_t poll();

 private:
  using TaskBase = detail::Callable<Finish>;
  template <class F>
  using Task = detail::CallableOf<Finish, F>;
  struct Entry {
    std::int64_t pixels = 0;
    std::unique_ptr<TaskBase> task;
    bool background = false;
    std::chrono::steady_clock::time_point queued_at{};  // background jobs: when posted
  };

  void enqueue(Owner owner, std::int64_t pixels, std::unique_ptr<TaskBase> task);
  void enqueue_background(Owner owner, std::int64_t pixels, std::unique_ptr<TaskBase> task);
  // Under mutex_: a background job may start now (no live job queued, a lane left, room).
  bool take_background(Entry& out);
  void finished(const Entry& e);  // under mutex_: a job's lane and pixels are free again
  void lane_loop();
  // Under mutex_: the next owner's next job when it may start now (nullopt-like empty Entry).
  bool take_next(Entry& out);
  // Runs e's job; returns its finish (empty: none, or the job threw).
  static Finish run_task(Entry& e);
  static void run_finish(Finish& finish);

  mutable std::mutex mutex_;
  std::condition_variable changed_;
  std::map<Owner, std::deque<Entry>> queues_;  // owners with queued jobs
  std::deque<Owner> turn_;                     // those owners, in the order they are served
  std::deque<Entry> background_;               // background jobs, FIFO
  int lane_count_ = 0;                         // start()'s lanes (lanes_ is not read under the mutex)
  int live_running_ = 0;                       // sessions' jobs running now
  int frames_per_lane_ = 1;
  std::chrono::milliseconds background_yield_{1000};
  std::size_t queued_ = 0;
  int running_ = 0;
  std::int64_t pixels_in_flight_ = 0;
  std::int64_t max_pixels_in_flight_ = 0;
  bool stopping_ = false;
  std::vector<std::thread> lanes_;
};

}  // namespace catgs::server
