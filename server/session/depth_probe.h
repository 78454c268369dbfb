// The answer to a DepthRequest (issue 38): the probe of render_core/cpu/pixel_depth.h on the
// scene's host model, whatever the renderer (CPU or CUDA), as a DepthResult. Runs on the worker
// pool, never on a session's strand (a probe visits every Gaussian: ~ms per million).
#pragma once

#include <cstdint>

#include <vector>

#include "forward_model/chunk_bounds.h"
#include "scene/gaussian_model.h"
#include "proto/message_validation.h"

namespace catgs::server {

// Probes `query` (validated by check_depth_request) and fills a DepthResult with request_id,
// hit, point, depth, opacity and server_ms; `error` when the probe throws. Never throws.
// `chunks`: the model's chunk bounds (LoadedScene::chunks), or null.
pb::DepthResult answer_depth(const GaussianModel& model, const std::vector<fm::ChunkBounds>* chunks,
                             const DepthQuery& query, std::uint32_t request_id);

}  // namespace catgs::server
