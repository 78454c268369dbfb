#include "session/depth_probe.h"

#include <chrono>
#include <exception>

#include "camera/camera.h"
#include "cpu/pixel_depth.h"

namespace catgs::server {

pb::DepthResult answer_depth(const GaussianModel& model, const std::vector<fm::ChunkBounds>* chunks,
                             const DepthQuery& query, std::uint32_t request_id) {
  pb::DepthResult r;
  r.set_request_id(request_id);
  const auto start = std::chrono::steady_clock::now();
  try {
    // The same camera as a frame of this pose and size (FramePipeline::render_into, frame_pipeline.cpp).
    const Camera camera = Camera::from_pose(query.pose.position, query.pose.orientation, query.pose.vertical_fov_deg,
                                            query.width, query.height);
    const cpu::PixelDepth d = cpu::probe_pixel_depth(model, camera, query.x, query.y, chunks);
    r.set_hit(d.hit);
    r.set_opacity(d.opacity);
    if (d.hit) {
      r.set_depth(d.depth);
      r.mutable_point()->set_x(d.point.x);
      r.mutable_point()->set_y(d.point.y);
      r.mutable_point()->set_z(d.point.z);
    }
  } catch (const std::exception& e) {
    r.set_error(std::string("depth probe: ") + e.what());
  }
  r.set_server_ms(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count());
  return r;
}

}  // namespace catgs::server
