// A first view of a scene for Welcome.initial_pose.
#pragma once

#include "catgs/gaussian_model.h"
#include "message_validation.h"

namespace catgs::server {

// Robust bounds of the means: per axis, the 2nd..98th percentile (outliers such as far
// background Gaussians would otherwise push the camera away). Falls back to model.bounds() for
// tiny models. Throws std::logic_error on an empty model.
Bounds robust_bounds(const GaussianModel& model);

// A camera looking at the centre of `bounds` from a distance at which the bounds' bounding
// sphere fits the view (vertical fov `fov_deg`, aspect width/height), placed in front and a
// little above. "Above" is world -y (3DGS captures are usually y-down); the camera's x axis stays
// horizontal (perpendicular to world y).
CameraPose initial_pose(const Bounds& bounds, float fov_deg, int width, int height);

}  // namespace catgs::server
