// A first view of a scene for Welcome.initial_pose.
#pragma once

#include "scene/gaussian_model.h"
#include "session/message_validation.h"

namespace catgs::server {

// The bounds a first view frames: the core's robust_bounds (scene/scene_bounds.h; per axis, the
// 2nd..98th percentile of the means, so far background Gaussians do not push the camera away),
// or model.bounds() for models under 100 Gaussians. Throws std::logic_error on an empty model.
Bounds first_view_bounds(const GaussianModel& model);

// A camera looking at the centre of `bounds` from a distance at which the bounds' bounding
// sphere fits the view (vertical fov `fov_deg`, aspect width/height), placed in front and a
// little above. "Above" is world -y (3DGS captures are usually y-down); the camera's x axis stays
// horizontal (perpendicular to world y).
CameraPose initial_pose(const Bounds& bounds, float fov_deg, int width, int height);

}  // namespace catgs::server
