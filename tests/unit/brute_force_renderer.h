// An independent, slow, per-pixel oracle for the forward model (docs/DESIGN.md "Forward model"),
// written apart from render_core (double precision, no tiles, no sort keys): each pixel gathers
// every Gaussian that reaches it, orders them by (view depth, index) and composites front to back.
#pragma once

#include "camera/camera.h"
#include "scene/gaussian_model.h"
#include "renderer/renderer.h"

namespace catgs::test {

// Real SH basis Y_0..Y_15 (the sign convention of the reference 3DGS), degree <= 3, at unit
// direction d, in double precision.
void sh_basis(glm::dvec3 d, double* y);

// vanilla = true: a Gaussian reaches a pixel only if the pixel's 16x16 tile lies in the tile
// rectangle of its 3-sigma square (reference 3DGS); false (exact): wherever alpha >= 1/255.
// Returns an image with rgb and rgba8 filled.
Image brute_force_render(const GaussianModel& model, const Camera& camera, bool vanilla,
                         glm::vec3 background = glm::vec3(0.0f));

}  // namespace catgs::test
