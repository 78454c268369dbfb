#include "render/gpu_assignment.h"

#include <algorithm>
#include <stdexcept>

namespace catgs::server {

std::vector<int> parse_gpus(const std::string& spec, int visible) {
  if (visible <= 0) throw std::invalid_argument("--gpus " + spec + ": no CUDA device is visible");
  std::vector<int> out;
  if (spec == "all") {
    for (int d = 0; d < visible; ++d) out.push_back(d);
    return out;
  }
  for (std::size_t at = 0; at <= spec.size();) {  // items between commas, empty ones too
    const std::size_t comma = std::min(spec.find(',', at), spec.size());
    const std::string item = spec.substr(at, comma - at);
    at = comma + 1;
    if (item.empty() || item.find_first_not_of("0123456789") != std::string::npos || item.size() > 4)
      throw std::invalid_argument("--gpus " + spec + ": '" + item + "' is not a device number");
    const int d = std::stoi(item);
    if (d >= visible)
      throw std::invalid_argument("--gpus " + spec + ": device " + item + " is not visible (" +
                                  std::to_string(visible) + " visible: 0.." + std::to_string(visible - 1) + ")");
    if (std::find(out.begin(), out.end(), d) != out.end())
      throw std::invalid_argument("--gpus " + spec + ": device " + item + " is listed twice");
    out.push_back(d);
  }
  if (out.empty()) throw std::invalid_argument("--gpus: empty list (all, or device numbers such as 0,1)");
  return out;
}

GpuAssignment::GpuAssignment(std::vector<int> devices) : devices_(std::move(devices)), sessions_(devices_.size(), 0) {}

int GpuAssignment::acquire() {
  const std::lock_guard<std::mutex> lock(mutex_);
  if (devices_.empty()) return -1;
  const auto least = std::min_element(sessions_.begin(), sessions_.end()) - sessions_.begin();
  ++sessions_[static_cast<std::size_t>(least)];
  return devices_[static_cast<std::size_t>(least)];
}

void GpuAssignment::release(int device) {
  const std::lock_guard<std::mutex> lock(mutex_);
  const auto it = std::find(devices_.begin(), devices_.end(), device);
  if (it == devices_.end()) return;
  auto& n = sessions_[static_cast<std::size_t>(it - devices_.begin())];
  if (n > 0) --n;
}

std::vector<std::int64_t> GpuAssignment::sessions() const {
  const std::lock_guard<std::mutex> lock(mutex_);
  return sessions_;
}

}  // namespace catgs::server
