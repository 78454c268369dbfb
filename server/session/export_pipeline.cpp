// A Session's video export (issue 38, "Export video" in the page's Paths panel; video_export.h):
// ExportVideoRequest is rate limited, authorised (role author or admin, as SaveAnnotations: an
// export costs minutes of rendering and a file on the server's disk, which a tour's viewers
// should not be able to start), checked against the --export-max-* caps, and then rendered one
// frame per background job on the render lanes, so that live sessions' frames go first. The page
// hears ExportProgress about four times a second, then gets the file as ExportChunks, a few
// queued at a time so that live frames do not wait behind megabytes. Every refusal is an
// ExportProgress with `error`; the session goes on. Closing the session ends its export and
// deletes its file.
#include <boost/asio/post.hpp>

#include <algorithm>
#include <filesystem>
#include <iostream>

#include "session/session.h"

namespace catgs::server {

namespace {

constexpr auto kProgressEvery = std::chrono::milliseconds(250);
constexpr std::size_t kChunkBytes = 1 << 20;  // ExportChunk.data at most (proto)
// Messages queued to the transport (frames included) below which another chunk goes out: the
// download keeps the socket busy without a live frame waiting behind more than a few MiB.
constexpr std::size_t kMaxQueuedForChunk = 4;

}  // namespace

void Session::refuse_export(std::uint32_t export_id, const std::string& why) {
  std::cerr << "[session " << id_ << " " << session_id_ << "] export " << export_id << " refused: " << why << "\n";
  pb::ServerMessage m;
  m.mutable_export_progress()->set_export_id(export_id);
  m.mutable_export_progress()->set_error(why);
  send(m);
  shared_.metrics.count(ServerMetrics::ExportEnd::refused);
}

bool Session::may_export() const {
  const SessionSettings& o = shared_.settings;
  return video_export_built() && role_ >= Role::author && o.export_limits.max_concurrent > 0 &&
         !shared_.export_folder.empty();
}

void Session::handle_export(const pb::ExportVideoRequest& request) {
  const SessionSettings& o = shared_.settings;
  if (!within(export_bucket_, ServerMetrics::Limit::export_video, "ExportVideoRequests", o.rate_limits.export_video))
    return;
  const std::uint32_t id = request.export_id();
  if (!video_export_built())
    return refuse_export(id, "video export not built (this server was built with -DCATGS_VIDEO_EXPORT=OFF)");
  // A server without tokens has no authors: anyone who reaches it could otherwise fill its disk.
  if (role_ < Role::author)
    return refuse_export(id, o.tokens.empty() ? "this server exports no videos (it has no author tokens: --token-file)"
                                              : "exporting a video needs an author or admin token");
  if (state_ != State::open) return refuse_export(id, "the scene is not open yet");
  if (o.export_limits.max_concurrent == 0 || shared_.export_folder.empty())
    return refuse_export(id, "video export is off on this server (--export-max-concurrent 0)");
  if (export_)
    return refuse_export(
        id, "export " + std::to_string(export_->video->id()) + " is still running: cancel it or wait for its file");
  ExportPlan plan;
  if (auto bad = check_export_request(request, o.export_limits, plan)) return refuse_export(id, bad->reason);
  if (++shared_.metrics.exports_running > o.export_limits.max_concurrent) {
    shared_.metrics.exports_running--;
    return refuse_export(id, "the server is already rendering " + std::to_string(o.export_limits.max_concurrent) +
                                 " export(s) (--export-max-concurrent): try again later");
  }
  export_ = std::make_unique<Export>();
  export_->holds_slot = true;
  // x264 gets a quarter of the cores: live sessions' encoders keep the rest.
  const int threads = std::max(1, o.frame.encoder_policy.usable_cores / 4);
  export_->video =
      std::make_shared<VideoExport>(std::move(plan), scene_->model, shared_.renderer_kind, shared_.render_options,
                                    std::max(gpu_, 0), threads, shared_.export_folder);
  export_->started = export_->last_progress = Clock::now();
  const VideoExport& v = *export_->video;
  std::cerr << "[session " << id_ << " " << session_id_ << "] export " << id << ": " << v.frames_total() << " frames, "
            << request.width() << "x" << request.height() << " at " << request.fps() << " fps, "
            << (request.pipeline().empty() ? "exact" : request.pipeline()) << "\n";
  send_export_progress();
  post_export_step();
}

void Session::handle_export_cancel(const pb::ExportCancel& cancel) {
  if (!export_ || export_->video->id() != cancel.export_id()) return;  // over already, or never was
  std::cerr << "[session " << id_ << " " << session_id_ << "] export " << cancel.export_id() << " cancelled\n";
  send_export_progress({}, /*cancelled=*/true);
  end_export(ServerMetrics::ExportEnd::cancelled);
}

void Session::post_export_step() {
  std::shared_ptr<VideoExport> video = export_->video;
  const std::int64_t pixels = video->pixels();
  shared_.renders.post_background(id_, pixels, [self = shared_from_this(), video = std::move(video)] {
    bool finished = false;
    std::string error;
    try {
      finished = video->step();
    } catch (const std::exception& e) {
      error = e.what();
      if (error.empty()) error = "unknown error";
    }
    boost::asio::post(self->strand_, [self, video, finished, error] { self->on_export_step(video, finished, error); });
  });
}

void Session::on_export_step(const std::shared_ptr<VideoExport>& video, bool finished, const std::string& error) {
  // Cancelled, or the session ended, meanwhile: the last reference (the job's) deletes the file.
  if (!export_ || export_->video != video) return;
  if (!error.empty()) {
    std::cerr << "[session " << id_ << " " << session_id_ << "] export " << video->id() << " failed: " << error << "\n";
    send_export_progress("rendering failed: " + error);
    return end_export(ServerMetrics::ExportEnd::failed);
  }
  const auto now = Clock::now();
  if (!finished) {
    if (now - export_->last_progress >= kProgressEvery) {
      export_->last_progress = now;
      send_export_progress();
    }
    return post_export_step();
  }
  // Rendered: the slot goes to the next export; the file goes to the page.
  shared_.metrics.exports_running--;
  export_->holds_slot = false;
  std::error_code ec;
  const auto size = std::filesystem::file_size(video->path(), ec);
  export_->file = std::make_unique<std::ifstream>(video->path(), std::ios::binary);
  if (ec || size == 0 || !*export_->file) {
    send_export_progress("cannot read the finished file" + (ec ? ": " + ec.message() : std::string()));
    return end_export(ServerMetrics::ExportEnd::failed);
  }
  export_->size = static_cast<double>(size);
  export_->sending = true;
  std::cerr << "[session " << id_ << " " << session_id_ << "] export " << video->id() << " rendered in "
            << ms_between(export_->started, now) / 1000.0 << " s: " << size << " bytes\n";
  send_export_progress();
  send_export_chunks();
}

void Session::send_export_progress(const std::string& error, bool cancelled) {
  const VideoExport& v = *export_->video;
  pb::ServerMessage m;
  pb::ExportProgress* p = m.mutable_export_progress();
  p->set_export_id(v.id());
  p->set_frames_done(static_cast<std::uint32_t>(v.frames_done()));
  p->set_frames_total(static_cast<std::uint32_t>(v.frames_total()));
  p->set_duration_s(v.duration_s());
  p->set_error(error);
  p->set_cancelled(cancelled);
  if (export_->sending) {
    p->set_done(true);
    p->set_bytes(export_->size);
  } else if (v.frames_done() > 0 && error.empty() && !cancelled) {
    // The frames so far at their mean pace (a path's frames cost about the same).
    const double per_frame = ms_between(export_->started, Clock::now()) / v.frames_done();
    p->set_eta_ms(per_frame * (v.frames_total() - v.frames_done()));
  }
  send(m);
}

void Session::send_export_chunks() {
  Export& e = *export_;
  while (e.sent < e.size && shared_.transport.queued(id_) < kMaxQueuedForChunk) {
    const auto n = static_cast<std::size_t>(std::min<double>(kChunkBytes, e.size - e.sent));
    pb::ServerMessage m;
    pb::ExportChunk* c = m.mutable_export_chunk();
    c->set_export_id(e.video->id());
    c->set_offset(e.sent);
    std::string* data = c->mutable_data();
    data->resize(n);
    if (!e.file->read(data->data(), static_cast<std::streamsize>(n))) {
      send_export_progress("cannot read the finished file at byte " + std::to_string(static_cast<long long>(e.sent)));
      return end_export(ServerMetrics::ExportEnd::failed);
    }
    e.sent += static_cast<double>(n);
    c->set_last(e.sent >= e.size);
    send(m);
  }
  if (e.sent >= e.size) {
    std::cerr << "[session " << id_ << " " << session_id_ << "] export " << e.video->id() << " sent\n";
    end_export(ServerMetrics::ExportEnd::sent);  // the page has it (queued): the server's copy goes
  }
}

void Session::end_export(ServerMetrics::ExportEnd how) {
  if (!export_) return;
  shared_.metrics.export_frames_total += static_cast<std::uint64_t>(export_->video->frames_done());
  shared_.metrics.count(how);
  export_->video->cancel();  // a step in flight renders nothing more
  if (export_->holds_slot) shared_.metrics.exports_running--;
  export_.reset();  // the file goes with the last reference (a step job's, when one runs)
}

}  // namespace catgs::server
