#include "base/allocation_faults.h"

#include <cstdlib>
#include <memory>
#include <mutex>
#include <random>

namespace catgs {

namespace {

std::mutex& hook_mutex() {
  static std::mutex m;
  return m;
}

// Shared, so that a call in flight keeps the hook it read while another thread replaces it.
std::shared_ptr<const AllocationFault>& hook() {
  static std::shared_ptr<const AllocationFault> h;
  return h;
}

}  // namespace

void set_allocation_fault(AllocationFault fault) {
  auto next = fault ? std::make_shared<const AllocationFault>(std::move(fault)) : nullptr;
  const std::lock_guard<std::mutex> lock(hook_mutex());
  hook() = std::move(next);
}

bool allocation_fault(std::uint64_t bytes, const char* what) {
  std::shared_ptr<const AllocationFault> h;
  {
    const std::lock_guard<std::mutex> lock(hook_mutex());
    h = hook();
  }
  return h && (*h)(bytes, what);
}

void throw_out_of_memory(const char* core, const char* what, std::uint64_t bytes, const std::string& why) {
  throw OutOfMemoryError(std::string(core) + ": " + what + " buffer of " + std::to_string(bytes) + " bytes: " + why,
                         bytes);
}

AllocationFault random_allocation_fault(double probability, std::uint64_t seed) {
  struct Draws {
    std::mutex mutex;
    std::mt19937_64 rng;
  };
  auto draws = std::make_shared<Draws>();
  draws->rng.seed(seed);
  return [draws, probability](std::uint64_t, const char*) {
    const std::lock_guard<std::mutex> lock(draws->mutex);
    return std::uniform_real_distribution<double>(0.0, 1.0)(draws->rng) < probability;
  };
}

AllocationFault allocation_fault_from_environment() {
  const char* text = std::getenv("CATGS_FAIL_ALLOCATIONS");
  if (!text || !*text) return {};
  const std::string s = text;
  const auto bad = [&] {
    return std::invalid_argument("CATGS_FAIL_ALLOCATIONS='" + s +
                                 "': expected P or P,SEED (P a probability in [0, 1], SEED a whole number)");
  };
  char* end = nullptr;
  const double p = std::strtod(s.c_str(), &end);
  if (end == s.c_str() || !(p >= 0.0 && p <= 1.0)) throw bad();
  std::uint64_t seed = 1;
  if (*end == ',') {
    const char* digits = end + 1;
    if (*digits < '0' || *digits > '9') throw bad();
    seed = std::strtoull(digits, &end, 10);
  }
  if (*end != '\0') throw bad();
  return random_allocation_fault(p, seed);
}

}  // namespace catgs
