#include "render/gpu_assignment.h"

#include <algorithm>
#include <cstdio>
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

std::string memory_text(std::uint64_t bytes) {
  char buf[64];
  if (bytes >= (1ull << 30))
    std::snprintf(buf, sizeof buf, "%.1f GiB", static_cast<double>(bytes) / (1ull << 30));
  else
    std::snprintf(buf, sizeof buf, "%llu MiB", static_cast<unsigned long long>(bytes >> 20));
  return buf;
}

std::uint64_t GpuAssignment::Memory::room() const {
  if (capacity == 0) return UINT64_MAX;
  const std::uint64_t used = scenes + reserved;
  return used >= capacity ? 0 : capacity - used;
}

std::uint64_t GpuAssignment::Memory::driver_room(std::uint64_t free_reserve) const {
  if (driver_free == UINT64_MAX) return UINT64_MAX;
  const std::uint64_t growth = reserved > held ? reserved - held : 0;
  const std::uint64_t keep = free_reserve + growth;
  return driver_free > keep ? driver_free - keep : 0;
}

GpuAssignment::GpuAssignment(std::vector<int> devices, std::vector<std::uint64_t> capacity, FreeMemory free_memory,
                             std::uint64_t free_reserve)
    : devices_(std::move(devices)), free_memory_(std::move(free_memory)), free_reserve_(free_reserve) {
  const std::size_t n = std::max<std::size_t>(devices_.size(), 1);  // no GPUs: the host slot
  slots_.resize(n);
  for (std::size_t k = 0; k < n; ++k) {
    slots_[k].device = devices_.empty() ? -1 : devices_[k];
    slots_[k].capacity = k < capacity.size() ? capacity[k] : 0;
  }
}

int GpuAssignment::slot_of(int device) const {
  for (std::size_t k = 0; k < slots_.size(); ++k)
    if (slots_[k].device == device) return static_cast<int>(k);
  return -1;
}

void GpuAssignment::probe_locked() const {
  if (!free_memory_) return;
  for (Memory& m : slots_) m.driver_free = free_memory_(m.device);
}

GpuAssignment::Placement GpuAssignment::place(std::uint64_t bytes) {
  const std::lock_guard<std::mutex> lock(mutex_);
  probe_locked();
  Placement p;
  int best = -1;
  for (std::size_t k = 0; k < slots_.size(); ++k)
    if (room_locked(slots_[k]) >= bytes &&
        (best < 0 || slots_[k].sessions < slots_[static_cast<std::size_t>(best)].sessions))
      best = static_cast<int>(k);
  if (best < 0) {
    p.why = "no " + std::string(devices_.empty() ? "device-memory allowance" : "GPU") + " can hold another session (" +
            memory_text(bytes) + " needed;";
    for (const Memory& m : slots_) {
      p.why += (m.device >= 0 ? " gpu " + std::to_string(m.device) : std::string(" host")) + ": " +
               memory_text(m.room()) + " free of " + memory_text(m.capacity) + " by the server's accounting";
      if (m.driver_free != UINT64_MAX)
        p.why += ", " + memory_text(m.driver_room(free_reserve_)) + " by the driver (" + memory_text(m.driver_free) +
                 " free, less the " + memory_text(free_reserve_) + " reserve and " +
                 memory_text(m.reserved > m.held ? m.reserved - m.held : 0) + " its sessions may still take)" +
                 (m.driver_room(free_reserve_) < m.room() ? ": the driver binds" : ": the accounting binds");
      p.why += ", " + std::to_string(m.sessions) + " sessions;";
    }
    p.why.back() = ')';
    p.device = slots_[0].device;
    for (const Memory& m : slots_) p.driver_binds = p.driver_binds || m.room() >= bytes;
    return p;
  }
  Memory& m = slots_[static_cast<std::size_t>(best)];
  ++m.sessions;
  m.reserved += bytes;
  p.device = m.device;
  p.placed = true;
  return p;
}

void GpuAssignment::release(int device, std::uint64_t bytes, std::uint64_t held) {
  const std::lock_guard<std::mutex> lock(mutex_);
  const int k = slot_of(device);
  if (k < 0) return;
  Memory& m = slots_[static_cast<std::size_t>(k)];
  if (m.sessions > 0) --m.sessions;
  m.reserved -= std::min(m.reserved, bytes);
  m.held -= std::min(m.held, held);
}

void GpuAssignment::hold(int device, std::uint64_t from, std::uint64_t to) {
  const std::lock_guard<std::mutex> lock(mutex_);
  const int k = slot_of(device);
  if (k < 0) return;
  Memory& m = slots_[static_cast<std::size_t>(k)];
  m.held = m.held - std::min(m.held, from) + to;
}

bool GpuAssignment::update(int device, std::uint64_t from, std::uint64_t to) {
  const std::lock_guard<std::mutex> lock(mutex_);
  const int k = slot_of(device);
  if (k < 0) return true;
  Memory& m = slots_[static_cast<std::size_t>(k)];
  m.reserved = m.reserved - std::min(m.reserved, from) + to;
  return m.capacity == 0 || m.scenes + m.reserved <= m.capacity;
}

std::shared_ptr<void> GpuAssignment::add_scene(int device, std::uint64_t bytes) {
  {
    const std::lock_guard<std::mutex> lock(mutex_);
    const int k = slot_of(device);
    if (k < 0) return nullptr;
    slots_[static_cast<std::size_t>(k)].scenes += bytes;
  }
  // The hold's deleter gives the bytes back; the assignment outlives every scene (Server order).
  return std::shared_ptr<void>(nullptr, [this, device, bytes](void*) {
    const std::lock_guard<std::mutex> lock(mutex_);
    const int k = slot_of(device);
    if (k >= 0)
      slots_[static_cast<std::size_t>(k)].scenes -= std::min(slots_[static_cast<std::size_t>(k)].scenes, bytes);
  });
}

std::vector<std::int64_t> GpuAssignment::sessions() const {
  const std::lock_guard<std::mutex> lock(mutex_);
  std::vector<std::int64_t> out;
  if (devices_.empty()) return out;
  for (const Memory& m : slots_) out.push_back(m.sessions);
  return out;
}

std::vector<GpuAssignment::Memory> GpuAssignment::memory() const {
  const std::lock_guard<std::mutex> lock(mutex_);
  probe_locked();
  return slots_;
}

std::uint64_t GpuAssignment::largest_room(std::string* binds) const {
  const std::lock_guard<std::mutex> lock(mutex_);
  probe_locked();
  std::uint64_t best = 0;
  for (const Memory& m : slots_) {
    const std::uint64_t room = room_locked(m);
    if (room < best || (room == best && best > 0)) continue;
    best = room;
    if (binds) *binds = m.driver_room(free_reserve_) < m.room() ? "driver" : "accounting";
  }
  return best;
}

}  // namespace catgs::server
