// A session's video export ("Export video" in the page's Paths panel; video_export.h renders
// it). ExportVideoRequest is authorised (role author or admin, as SaveAnnotations: an export costs
// minutes of rendering and a file on the server's disk, which a tour's viewers should not be able
// to start), checked against the --export-max-* caps, and then rendered one frame per background
// job on the render lanes, so that live sessions' frames go first. The page hears ExportProgress
// about four times a second, then gets the file as ExportChunks, a few queued at a time so that
// live frames do not wait behind megabytes. Every refusal is an ExportProgress with `error`; the
// session goes on. Closing the session ends its export and deletes its file.
//
// Threading: every call on the owning session's strand; the render steps run on the lanes and
// come back through the strand (SessionOwner, session_shared.h). One export at a time.
#pragma once

#include <chrono>
#include <cstdint>
#include <fstream>
#include <memory>
#include <string>

#include "scene/gaussian_model.h"
#include "session/access_tokens.h"
#include "session/session_shared.h"
#include "session/video_export.h"

namespace catgs::server {

class SessionExport {
 public:
  SessionExport(SessionShared& shared, ConnId id, SessionOwner& owner) : shared_(shared), id_(id), owner_(owner) {}
  ~SessionExport() { end(ServerMetrics::ExportEnd::cancelled); }
  SessionExport(const SessionExport&) = delete;
  SessionExport& operator=(const SessionExport&) = delete;

  // Whether a session of `role` would get past the build, folder and role checks (Welcome's
  // can_export): the page hides what the server would refuse anyway.
  bool may_export(Role role) const;
  // ExportVideoRequest (already rate limited by the session): refused with a reason, or started.
  // `open`: the session's scene is open; `model`: its scene; `gpu`: its CUDA device (-1: CPU).
  void start(const pb::ExportVideoRequest& request, Role role, bool open, std::shared_ptr<const GaussianModel> model,
             int gpu);
  // ExportCancel: ends the export it names, if it still runs.
  void cancel(const pb::ExportCancel& cancel);
  // The transport took a message, or the tick: the finished file's next chunks, if it is sending.
  void pump();
  // Ends the export, if any: its slot (if still rendering) and its file go.
  void end(ServerMetrics::ExportEnd how);

 private:
  using Clock = std::chrono::steady_clock;
  void refuse(std::uint32_t export_id, const std::string& why);  // ExportProgress.error
  void post_step();                                              // the next frame, at low priority
  // A step of `video` ended (finished: the file is complete; error: it failed).
  void on_step(const std::shared_ptr<VideoExport>& video, bool finished, const std::string& error);
  // The running export's state (ExportProgress); `error` / `cancelled`: how it ended.
  void send_progress(const std::string& error = {}, bool cancelled = false);
  void send_chunks();  // the finished file's next chunks, a few queued at a time

  SessionShared& shared_;
  const ConnId id_;
  SessionOwner& owner_;
  // The export: rendering (a step job in flight or not), then sending its file. Null when none.
  struct Running {
    std::shared_ptr<VideoExport> video;
    bool holds_slot = false;  // counts in metrics.exports_running (while rendering)
    bool sending = false;     // finished: its file goes out in chunks
    Clock::time_point started, last_progress;
    std::unique_ptr<std::ifstream> file;
    double size = 0, sent = 0;  // bytes
  };
  std::unique_ptr<Running> run_;
};

}  // namespace catgs::server
