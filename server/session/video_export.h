// "Export video" (issue 38): a session's camera path rendered to an H.264 MP4 on the server
// (proto ExportVideoRequest), with the same code as `catgs-render --video`
// (encode/tour_video.h), one frame per background job on the render lanes (render_scheduler.h:
// live sessions' renders go first), into a temporary file that the session then sends to the
// page in ExportChunk messages and deletes. The session's side (authorisation, caps, progress,
// chunks, cancel) is session/session_export.h; the request's checks are
// check_export_request (message_validation.h).
//
// Why the file goes over the WebSocket rather than HTTP: the session is already authorised (its
// Hello token), the transport already paces large messages in fragments, and the file dies with
// the session; an HTTP download would need a second, one-time credential in a URL (which leaks
// into logs and histories) and a dynamic HTTP handler the transport does not have (it serves
// only static files, /healthz, /readyz, /metrics and /scenes).
//
// A server built with -DCATGS_VIDEO_EXPORT=OFF (no libavformat: the GPU host's packed server,
// scripts/gpu_server_run.sh) has this interface with video_export_built() false; step() then
// throws "video export not built".
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>

#include "renderer/renderer.h"
#include "scene/gaussian_model.h"
#include "proto/message_validation.h"

namespace catgs::server {

// True when this server was built with video export (CMake option CATGS_VIDEO_EXPORT).
bool video_export_built();

// The folder of the export files: `dir` (--export-dir), or TMPDIR/catgs-exports when empty;
// created when missing. Throws std::runtime_error naming the folder when it cannot be made.
std::string export_folder(const std::string& dir);
// Deletes the catgs-export-*.mp4 files an earlier run left in `folder` (a crash, a kill): at
// start-up. Returns how many it deleted; never throws (a file it cannot delete is skipped).
int remove_stale_exports(const std::string& folder);

class VideoExport {
 public:
  // `plan` from check_export_request; the scene's model; the server's renderer kind ("cpu" or
  // "cuda"), render options (the plan's pipeline replaces theirs) and the session's GPU (or 0);
  // x264's threads. Opens nothing: the renderer, the encoder and the file are opened by the first
  // step(), on a render lane. The file will be FOLDER/catgs-export-<128 random bits>.mp4.
  VideoExport(ExportPlan plan, std::shared_ptr<const GaussianModel> model, std::string renderer_kind,
              RenderOptions options, int gpu, int encoder_threads, const std::string& folder);
  ~VideoExport();  // deletes the file, finished or not
  VideoExport(const VideoExport&) = delete;
  VideoExport& operator=(const VideoExport&) = delete;

  // On a render lane, one at a time: renders and encodes the next frame, and after the last one
  // finishes the file. Returns true when the file is finished (then never called again). After
  // cancel(), does nothing and returns false. Throws what the renderer, the encoder (a size past
  // H.264's level) and the file (a full disk) throw, and std::runtime_error "video export not
  // built" in a server built without it.
  bool step();
  // Any thread: later steps do nothing (one running finishes its frame).
  void cancel() { cancelled_ = true; }
  bool cancelled() const { return cancelled_; }

  std::uint32_t id() const { return plan_.export_id; }
  int frames_done() const { return frames_done_; }
  int frames_total() const { return static_cast<int>(plan_.frames.size()); }
  double duration_s() const { return plan_.duration_s; }
  std::int64_t pixels() const { return static_cast<std::int64_t>(plan_.width) * plan_.height; }
  const std::string& path() const { return path_; }

 private:
  struct Writer;  // the renderer and the TourVideo, opened by the first step()

  ExportPlan plan_;
  std::shared_ptr<const GaussianModel> model_;
  std::string renderer_kind_;
  RenderOptions options_;
  int gpu_ = 0;
  int encoder_threads_ = 0;
  std::string path_;
  std::shared_ptr<Writer> writer_;  // shared_ptr: Writer is complete only where it is built
  std::atomic<int> frames_done_{0};
  std::atomic<bool> cancelled_{false};
};

}  // namespace catgs::server
