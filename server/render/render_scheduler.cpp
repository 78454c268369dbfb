#include "render/render_scheduler.h"

#include <iostream>

#include "process/thread_name.h"

namespace catgs::server {

namespace {
thread_local int this_lane = -1;  // the lane a job runs on (-1: not a lane thread)
}  // namespace

int RenderScheduler::current_lane() { return this_lane; }

RenderScheduler::~RenderScheduler() {
  if (!lanes_.empty()) stop();
}

int RenderScheduler::default_lanes(int requested, const std::string& renderer_kind, int threads) {
  if (requested > 0) return requested;
  return renderer_kind == "cuda" ? 4 : threads;
}

int RenderScheduler::default_frames_per_lane(int requested, const std::string& renderer_kind) {
  if (requested > 0) return requested;
  return renderer_kind == "cuda" ? 2 : 1;
}

void RenderScheduler::start(int lanes, std::int64_t max_pixels_in_flight) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = false;
    max_pixels_in_flight_ = max_pixels_in_flight;
    lane_count_ = lanes;
  }
  for (int i = 0; i < lanes; ++i)
    lanes_.emplace_back([this, i] {
      this_lane = i;
      name_this_thread("catgs-lane" + std::to_string(i));
      lane_loop();
    });
}

void RenderScheduler::enqueue(Owner owner, std::int64_t pixels, std::unique_ptr<TaskBase> task) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    auto& q = queues_[owner];
    if (q.empty()) turn_.push_back(owner);  // joins the round at its end
    q.push_back(Entry{pixels, std::move(task)});
    ++queued_;
  }
  changed_.notify_all();  // drain() waits on the same condition: a lane must be among the woken
}

void RenderScheduler::enqueue_background(Owner, std::int64_t pixels, std::unique_ptr<TaskBase> task) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    background_.push_back(Entry{pixels, std::move(task), true, std::chrono::steady_clock::now()});
    ++queued_;
  }
  changed_.notify_all();
}

bool RenderScheduler::take_background(Entry& out) {
  if (background_.empty()) return false;
  // One lane stays for live work when there are several (poll() runs with no lanes at all).
  if (lane_count_ > 1 && running_ >= lane_count_ - 1) return false;
  // A live render running shares the device (or the cores) with it: wait for a gap, up to the
  // yield time (then run anyway, so that a busy server still exports).
  if (live_running_ > 0 && std::chrono::steady_clock::now() < background_.front().queued_at + background_yield_)
    return false;
  const std::int64_t pixels = background_.front().pixels;
  if (running_ > 0 && pixels_in_flight_ + pixels > max_pixels_in_flight_) return false;
  out = std::move(background_.front());
  background_.pop_front();
  --queued_;
  ++running_;
  pixels_in_flight_ += pixels;
  return true;
}

void RenderScheduler::finished(const Entry& e) {
  --running_;
  if (!e.background) --live_running_;
  pixels_in_flight_ -= e.pixels;
}

bool RenderScheduler::take_next(Entry& out) {
  // Live work first: a background job only when no session's job is queued.
  if (turn_.empty()) return take_background(out);
  const Owner owner = turn_.front();
  auto it = queues_.find(owner);
  const std::int64_t pixels = it->second.front().pixels;
  // The cap: room for this job, or nothing else running (a job over the cap runs alone).
  if (running_ > 0 && pixels_in_flight_ + pixels > max_pixels_in_flight_) return false;
  out = std::move(it->second.front());
  it->second.pop_front();
  turn_.pop_front();
  if (it->second.empty())
    queues_.erase(it);
  else
    turn_.push_back(owner);  // one job per owner per round
  --queued_;
  ++running_;
  ++live_running_;
  pixels_in_flight_ += pixels;
  return true;
}

RenderScheduler::Finish RenderScheduler::run_task(Entry& e) {
  Finish finish;
  try {
    finish = e.task->run();
  } catch (const std::exception& ex) {
    std::cerr << "render lane: a job threw: " << ex.what() << "\n";
  } catch (...) {
    std::cerr << "render lane: a job threw\n";
  }
  e.task.reset();  // the job's captures (a session, its buffers) go before the lane waits again
  return finish;
}

void RenderScheduler::run_finish(Finish& finish) {
  try {
    finish();
  } catch (const std::exception& ex) {
    std::cerr << "render lane: a frame's finish threw: " << ex.what() << "\n";
  } catch (...) {
    std::cerr << "render lane: a frame's finish threw\n";
  }
  finish = Finish();  // its captures go now, as a job's
}

void RenderScheduler::lane_loop() {
  // This lane's frames in flight, oldest first: each job's entry (running until its finish) and
  // its finish.
  std::deque<std::pair<Entry, Finish>> begun;
  std::unique_lock<std::mutex> lock(mutex_);
  for (;;) {
    Entry e;
    bool took = false;
    while (!stopping_) {
      if (!begun.empty() && begun.front().second.ready()) break;  // done on the GPU: finish it first
      if (static_cast<int>(begun.size()) < frames_per_lane_ && take_next(e)) {
        took = true;
        break;
      }
      if (!begun.empty()) break;  // finish the oldest frame rather than wait
      // A background job waiting for a gap in the live renders is due at its yield's end.
      const auto due = background_.empty() ? std::chrono::steady_clock::time_point::max()
                                           : background_.front().queued_at + background_yield_;
      if (due > std::chrono::steady_clock::now() && due != std::chrono::steady_clock::time_point::max())
        changed_.wait_until(lock, due);
      else
        changed_.wait(lock);
    }
    if (!took) {
      if (begun.empty()) return;  // stopping, and no frame left to finish
      auto [entry, finish] = std::move(begun.front());
      begun.pop_front();
      lock.unlock();
      run_finish(finish);
      lock.lock();
      finished(entry);
      changed_.notify_all();
      continue;
    }
    lock.unlock();
    Finish finish = run_task(e);
    lock.lock();
    if (finish) {  // running until its finish
      begun.emplace_back(std::move(e), std::move(finish));
      continue;
    }
    finished(e);
    // Room freed: any lane may now start the next owner's job; drain() may be waiting too.
    changed_.notify_all();
  }
}

std::size_t RenderScheduler::queued() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return queued_;
}

std::int64_t RenderScheduler::pixels_in_flight() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return pixels_in_flight_;
}

bool RenderScheduler::drain(std::chrono::steady_clock::time_point deadline) {
  std::unique_lock<std::mutex> lock(mutex_);
  return changed_.wait_until(lock, deadline, [&] { return queued_ == 0 && running_ == 0; });
}

void RenderScheduler::stop() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
  }
  changed_.notify_all();
  for (auto& t : lanes_) t.join();
  lanes_.clear();
}

std::size_t RenderScheduler::poll() {
  std::size_t ran = 0;
  for (;;) {
    Entry e;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (!take_next(e)) return ran;
    }
    Finish finish = run_task(e);
    if (finish) run_finish(finish);
    {
      std::lock_guard<std::mutex> lock(mutex_);
      finished(e);
    }
    ++ran;
  }
}

}  // namespace catgs::server
