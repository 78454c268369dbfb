// The traces of one catgs-loadgen run, each made once and shared by every session that replays it
// (issue 92). Fitting a real path onto a scene (fit_trace_to_scene, estimate_up) reads every
// Gaussian: on a 107-220 M Gaussian city that is seconds of a core, and made once per session at
// every ramp step it took more of the host's cores than the server did, so those ramps measured
// the client as much as the server.
#pragma once

#include <future>
#include <map>
#include <memory>
#include <mutex>
#include <string>

#include "camera/trace.h"
#include "catgs_stream.pb.h"
#include "scene/gaussian_model.h"

namespace catgs::loadgen {

class TraceCache {
 public:
  // The trace of `spec` at width x height (make_load_trace, load_session.h). The first caller for
  // a key makes it on its own thread; callers that come meanwhile wait for it, later ones get it
  // at once. The key is the spec, the size, the scene and, for "orbit", the Welcome's view and
  // bounds (its trace is made from them). Throws what make_load_trace throws, to every caller of
  // that key (a bad file stays bad).
  std::shared_ptr<const Trace> get(const std::string& spec, const GaussianModel* scene,
                                   const ::catgs::stream::v1::Welcome& welcome, int width, int height);
  // Traces made so far (each key once; the run's report records it, a test reads it).
  int made() const;

 private:
  mutable std::mutex mutex_;
  std::map<std::string, std::shared_future<std::shared_ptr<const Trace>>> traces_;
};

}  // namespace catgs::loadgen
