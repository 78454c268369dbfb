// A session's video export (session_export.h).
#include "session/session_export.h"

#include <boost/asio/post.hpp>

#include <algorithm>
#include <filesystem>
#include <iostream>

#include "session/frame_pipeline.h"  // ms_between

namespace catgs::server {

namespace {

constexpr auto kProgressEvery = std::chrono::milliseconds(250);
constexpr std::size_t kChunkBytes = 1 << 20;  // ExportChunk.data at most (proto)
// Messages queued to the transport (frames included) below which another chunk goes out: the
// download keeps the socket busy without a live frame waiting behind more than a few MiB.
constexpr std::size_t kMaxQueuedForChunk = 4;

}  // namespace

void SessionExport::refuse(std::uint32_t export_id, const std::string& why) {
  std::cerr << owner_.label() << " export " << export_id << " refused: " << why << "\n";
  pb::ServerMessage m;
  m.mutable_export_progress()->set_export_id(export_id);
  m.mutable_export_progress()->set_error(why);
  owner_.send(m);
  shared_.metrics.count(ServerMetrics::ExportEnd::refused);
}

bool SessionExport::may_export(Role role) const {
  const SessionSettings& o = shared_.settings;
  return video_export_built() && role >= Role::author && o.export_limits.max_concurrent > 0 &&
         !shared_.export_folder.empty();
}

void SessionExport::start(const pb::ExportVideoRequest& request, Role role, bool open,
                          std::shared_ptr<const GaussianModel> model, int gpu) {
  const SessionSettings& o = shared_.settings;
  const std::uint32_t id = request.export_id();
  if (!video_export_built())
    return refuse(id, "video export not built (this server was built with -DCATGS_VIDEO_EXPORT=OFF)");
  // A server without tokens has no authors: anyone who reaches it could otherwise fill its disk.
  if (role < Role::author)
    return refuse(id, o.tokens.empty() ? "this server exports no videos (it has no author tokens: --token-file)"
                                       : "exporting a video needs an author or admin token");
  if (!open) return refuse(id, "the scene is not open yet");
  if (o.export_limits.max_concurrent == 0 || shared_.export_folder.empty())
    return refuse(id, "video export is off on this server (--export-max-concurrent 0)");
  if (run_)
    return refuse(id,
                  "export " + std::to_string(run_->video->id()) + " is still running: cancel it or wait for its file");
  ExportPlan plan;
  if (auto bad = check_export_request(request, o.export_limits, plan)) return refuse(id, bad->reason);
  if (++shared_.metrics.exports_running > o.export_limits.max_concurrent) {
    shared_.metrics.exports_running--;
    return refuse(id, "the server is already rendering " + std::to_string(o.export_limits.max_concurrent) +
                          " export(s) (--export-max-concurrent): try again later");
  }
  run_ = std::make_unique<Running>();
  run_->holds_slot = true;
  // x264 gets a quarter of the cores: live sessions' encoders keep the rest.
  const int threads = std::max(1, o.frame.encoder_policy.usable_cores / 4);
  run_->video = std::make_shared<VideoExport>(std::move(plan), std::move(model), shared_.renderer_kind,
                                              shared_.render_options, std::max(gpu, 0), threads, shared_.export_folder);
  run_->started = run_->last_progress = Clock::now();
  const VideoExport& v = *run_->video;
  std::cerr << owner_.label() << " export " << id << ": " << v.frames_total() << " frames, " << request.width() << "x"
            << request.height() << " at " << request.fps() << " fps, "
            << (request.pipeline().empty() ? "exact" : request.pipeline()) << "\n";
  send_progress();
  post_step();
}

void SessionExport::cancel(const pb::ExportCancel& cancel) {
  if (!run_ || run_->video->id() != cancel.export_id()) return;  // over already, or never was
  std::cerr << owner_.label() << " export " << cancel.export_id() << " cancelled\n";
  send_progress({}, /*cancelled=*/true);
  end(ServerMetrics::ExportEnd::cancelled);
}

void SessionExport::post_step() {
  std::shared_ptr<VideoExport> video = run_->video;
  const std::int64_t pixels = video->pixels();
  shared_.renders.post_background(id_, pixels, [keep = owner_.keep_alive(), this, video = std::move(video)] {
    bool finished = false;
    std::string error;
    try {
      finished = video->step();
    } catch (const std::exception& e) {
      error = e.what();
      if (error.empty()) error = "unknown error";
    }
    boost::asio::post(owner_.strand(), [keep, this, video, finished, error] { on_step(video, finished, error); });
  });
}

void SessionExport::on_step(const std::shared_ptr<VideoExport>& video, bool finished, const std::string& error) {
  // Cancelled, or the session ended, meanwhile: the last reference (the job's) deletes the file.
  if (!run_ || run_->video != video) return;
  if (!error.empty()) {
    std::cerr << owner_.label() << " export " << video->id() << " failed: " << error << "\n";
    send_progress("rendering failed: " + error);
    return end(ServerMetrics::ExportEnd::failed);
  }
  const auto now = Clock::now();
  if (!finished) {
    if (now - run_->last_progress >= kProgressEvery) {
      run_->last_progress = now;
      send_progress();
    }
    return post_step();
  }
  // Rendered: the slot goes to the next export; the file goes to the page.
  shared_.metrics.exports_running--;
  run_->holds_slot = false;
  std::error_code ec;
  const auto size = std::filesystem::file_size(video->path(), ec);
  run_->file = std::make_unique<std::ifstream>(video->path(), std::ios::binary);
  if (ec || size == 0 || !*run_->file) {
    send_progress("cannot read the finished file" + (ec ? ": " + ec.message() : std::string()));
    return end(ServerMetrics::ExportEnd::failed);
  }
  run_->size = static_cast<double>(size);
  run_->sending = true;
  std::cerr << owner_.label() << " export " << video->id() << " rendered in " << ms_between(run_->started, now) / 1000.0
            << " s: " << size << " bytes\n";
  send_progress();
  send_chunks();
}

void SessionExport::send_progress(const std::string& error, bool cancelled) {
  const VideoExport& v = *run_->video;
  pb::ServerMessage m;
  pb::ExportProgress* p = m.mutable_export_progress();
  p->set_export_id(v.id());
  p->set_frames_done(static_cast<std::uint32_t>(v.frames_done()));
  p->set_frames_total(static_cast<std::uint32_t>(v.frames_total()));
  p->set_duration_s(v.duration_s());
  p->set_error(error);
  p->set_cancelled(cancelled);
  if (run_->sending) {
    p->set_done(true);
    p->set_bytes(run_->size);
  } else if (v.frames_done() > 0 && error.empty() && !cancelled) {
    // The frames so far at their mean pace (a path's frames cost about the same).
    const double per_frame = ms_between(run_->started, Clock::now()) / v.frames_done();
    p->set_eta_ms(per_frame * (v.frames_total() - v.frames_done()));
  }
  owner_.send(m);
}

void SessionExport::send_chunks() {
  Running& e = *run_;
  while (e.sent < e.size && shared_.transport.queued(id_) < kMaxQueuedForChunk) {
    const auto n = static_cast<std::size_t>(std::min<double>(kChunkBytes, e.size - e.sent));
    pb::ServerMessage m;
    pb::ExportChunk* c = m.mutable_export_chunk();
    c->set_export_id(e.video->id());
    c->set_offset(e.sent);
    std::string* data = c->mutable_data();
    data->resize(n);
    if (!e.file->read(data->data(), static_cast<std::streamsize>(n))) {
      send_progress("cannot read the finished file at byte " + std::to_string(static_cast<long long>(e.sent)));
      return end(ServerMetrics::ExportEnd::failed);
    }
    e.sent += static_cast<double>(n);
    c->set_last(e.sent >= e.size);
    owner_.send(m);
  }
  if (e.sent >= e.size) {
    std::cerr << owner_.label() << " export " << e.video->id() << " sent\n";
    end(ServerMetrics::ExportEnd::sent);  // the page has it (queued): the server's copy goes
  }
}

void SessionExport::pump() {
  if (run_ && run_->sending) send_chunks();
}

void SessionExport::end(ServerMetrics::ExportEnd how) {
  if (!run_) return;
  shared_.metrics.export_frames_total += static_cast<std::uint64_t>(run_->video->frames_done());
  shared_.metrics.count(how);
  run_->video->cancel();  // a step in flight renders nothing more
  if (run_->holds_slot) shared_.metrics.exports_running--;
  run_.reset();  // the file goes with the last reference (a step job's, when one runs)
}

}  // namespace catgs::server
