// Fuzz target: any bytes as a client WebSocket message: protobuf decode of ClientMessage, then
// the server's validation of whichever body it holds (proto/message_validation.h), as the
// session does before acting on a message. Violations are the expected answer; a crash, a
// sanitizer report or an exception is a finding.
#include <cstddef>
#include <cstdint>

#include "proto/message_validation.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  namespace pb = catgs::server::pb;
  pb::ClientMessage m;
  if (!m.ParseFromArray(data, static_cast<int>(size))) return 0;
  catgs::server::Viewport viewport;
  catgs::server::CameraPose pose;
  switch (m.body_case()) {
    case pb::ClientMessage::kHello:
      (void)catgs::server::check_hello(m.hello(), catgs::server::ViewportLimit{}, viewport);
      break;
    case pb::ClientMessage::kPose:
      (void)catgs::server::check_pose(m.pose(), pose);
      break;
    case pb::ClientMessage::kResize:
      (void)catgs::server::check_viewport(m.resize().viewport_width(), m.resize().viewport_height(),
                                          catgs::server::ViewportLimit{}, viewport);
      break;
    case pb::ClientMessage::kQuality:
      (void)catgs::server::check_quality(m.quality());
      break;
    case pb::ClientMessage::kExportVideo: {
      catgs::server::ExportPlan plan;  // a valid path is sampled at its fps (36000 frames at most)
      (void)catgs::server::check_export_request(m.export_video(), catgs::server::ExportLimits{}, plan);
      break;
    }
    default:
      break;
  }
  return 0;
}
