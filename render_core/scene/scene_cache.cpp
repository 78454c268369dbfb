// The scene cache (scene_cache.h): header checks, block hashes, parallel write and copy-out.
#include "scene/scene_cache.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstddef>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <vector>

#define XXH_INLINE_ALL  // header-only: nothing to link (the GPU machine's build carries the header)
#include <xxhash.h>

#include "forward_model/sh_storage.h"
#include "scene/compact_file.h"
#include "scene/file_write.h"
#include "ply_format.h"
#include "scene/load_blocks.h"
#include "scene/scene_peek.h"

namespace catgs {

namespace {

constexpr char kMagic[8] = {'C', 'A', 'T', 'G', 'S', 'C', 'A', 'C'};
constexpr uint32_t kEndian = 0x01020304u;
constexpr uint64_t kAlign = 4096;
constexpr uint64_t kHeadBytes = 64 * 1024;  // of the source, hashed
enum Section { kMeans, kLogScales, kRotations, kOpacity, kSh, kShHalf, kChunks, kLod, kSections };
const char* const kSectionNames[kSections] = {"means", "log_scales", "rotations", "opacity",
                                              "sh",    "sh_half",    "chunks",    "lod"};

struct CacheHeader {
  char magic[8];
  uint32_t version;
  uint32_t endian;
  uint64_t gaussians;
  uint32_t sh_degree;
  uint32_t chunk_size;
  uint64_t lod_nodes;  // 0 (no LOD) or chunk_count(gaussians)
  SourceStamp source;
  uint64_t block_bytes;
  uint64_t offset[kSections];
  uint64_t bytes[kSections];
  uint64_t hashes_offset;  // the block hashes
  uint64_t hash_count;
  uint64_t hashes_hash;  // XXH3 of the block hash table
  uint64_t file_size;
  uint64_t header_hash;  // XXH3 of every byte above
};
static_assert(sizeof(CacheHeader) < kAlign, "the header fits its reserved page");

uint64_t align_up(uint64_t x) { return (x + kAlign - 1) / kAlign * kAlign; }
uint64_t blocks_of(uint64_t bytes) { return (bytes + kCacheBlockBytes - 1) / kCacheBlockBytes; }

}  // namespace

SourceStamp source_stamp(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) throw SceneFileError(path, std::string("cannot stat: ") + std::strerror(errno));
  SourceStamp s;
  s.size = static_cast<uint64_t>(st.st_size);
  s.mtime_ns = static_cast<int64_t>(st.st_mtim.tv_sec) * 1000000000 + st.st_mtim.tv_nsec;
  if (S_ISDIR(st.st_mode)) return s;
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throw SceneFileError(path, std::string("cannot open: ") + std::strerror(errno));
  std::vector<char> head(static_cast<std::size_t>(std::min(s.size, kHeadBytes)));
  const ssize_t got = ::pread(fd, head.data(), head.size(), 0);
  ::close(fd);
  if (got != static_cast<ssize_t>(head.size())) throw SceneFileError(path, "cannot read its first bytes");
  s.head_hash = XXH3_64bits(head.data(), head.size());
  return s;
}

namespace {

// The layout of a model's cache: section sizes and offsets, the hash table's place.
CacheHeader layout(uint64_t n, int sh_degree, bool lod) {
  CacheHeader h{};
  std::memcpy(h.magic, kMagic, sizeof kMagic);
  h.version = kSceneCacheVersion;
  h.endian = kEndian;
  h.gaussians = n;
  h.sh_degree = static_cast<uint32_t>(sh_degree);
  h.chunk_size = fm::kChunkSize;
  h.block_bytes = kCacheBlockBytes;
  h.lod_nodes = lod ? fm::chunk_count(n) : 0;
  const uint64_t sh = n * static_cast<uint64_t>(sh_coeff_count(sh_degree)) * 3;
  const uint64_t bytes[kSections] = {3 * n * 4,
                                     3 * n * 4,
                                     4 * n * 4,
                                     n * 4,
                                     sh * 4,
                                     sh * 2,
                                     fm::chunk_count(n) * sizeof(fm::ChunkBounds),
                                     h.lod_nodes * sizeof(fm::LodNode)};
  h.hash_count = 0;
  for (int s = 0; s < kSections; ++s) {
    h.bytes[s] = bytes[s];
    h.hash_count += blocks_of(bytes[s]);
  }
  h.hashes_offset = kAlign;
  uint64_t at = align_up(h.hashes_offset + 8 * h.hash_count);
  for (int s = 0; s < kSections; ++s) {
    h.offset[s] = at;
    at = align_up(at + h.bytes[s]);
  }
  h.file_size = at;
  return h;
}

uint64_t header_hash(const CacheHeader& h) { return XXH3_64bits(&h, offsetof(CacheHeader, header_hash)); }

// One hashed block: section s, bytes [begin, end) of it, hash slot `slot`.
struct Block {
  int section;
  uint64_t begin, end, slot;
};
std::vector<Block> blocks(const CacheHeader& h) {
  std::vector<Block> out;
  for (int s = 0; s < kSections; ++s)
    for (uint64_t b = 0; b < h.bytes[s]; b += kCacheBlockBytes)
      out.push_back({s, b, std::min(h.bytes[s], b + kCacheBlockBytes), out.size()});
  return out;
}

const void* float_section(const GaussianModel& m, int s) {
  switch (s) {
    case kMeans:
      return m.means.data();
    case kLogScales:
      return m.log_scales.data();
    case kRotations:
      return m.rotations.data();
    case kOpacity:
      return m.opacity_logits.data();
    case kSh:
      return m.sh.data();
    default:
      return nullptr;
  }
}
void* float_section(GaussianModel& m, int s) {
  return const_cast<void*>(float_section(static_cast<const GaussianModel&>(m), s));
}

// The scene readers' own check (GaussianModel::validate: every value finite), on the block just
// copied into `m` while it is in cache: the hashes prove a cache is intact, not that its writer
// was this program (anyone can compute XXH3), so a forged cache must not let in what the scene's
// loader refuses. Throws SceneCacheRejected naming the cache, the Gaussian and the property.
void check_finite(const GaussianModel& m, const Block& b, const std::string& cache_path) {
  static const char* const kWhat[] = {"mean", "log-scale", "rotation", "opacity", "SH coefficient"};
  const std::size_t stride[] = {3, 3, 4, 1, static_cast<std::size_t>(m.sh_coeffs()) * 3};
  const auto* v = static_cast<const float*>(float_section(m, b.section)) + b.begin / 4;
  const std::size_t count = (b.end - b.begin) / 4, k = first_non_finite(v, count);
  if (k < count)
    throw SceneCacheRejected(cache_path, std::string("non-finite ") + kWhat[b.section] + " of Gaussian " +
                                             std::to_string((b.begin / 4 + k) / stride[b.section]) +
                                             " (a scene loader refuses it)");
}

}  // namespace

std::string scene_cache_path(const std::string& scene_path) { return scene_path + ".catgs-cache"; }

std::string derived_file_path(const std::string& scene_path, const std::string& suffix, const std::string& folder) {
  if (folder.empty()) return scene_path + suffix;
  uint64_t key = 0;
  try {
    const SourceStamp s = source_stamp(scene_path);
    const uint64_t parts[2] = {s.size, s.head_hash};
    key = XXH3_64bits(parts, sizeof parts);
  } catch (const SceneFileError&) {
    key = XXH3_64bits(scene_path.data(), scene_path.size());
  }
  char hex[17];
  std::snprintf(hex, sizeof hex, "%016llx", static_cast<unsigned long long>(key));
  const std::string name = std::filesystem::path(scene_path).filename().string();
  return (std::filesystem::path(folder) / (name + "." + hex + suffix)).string();
}

std::string default_cache_folder() {
  const char* xdg = std::getenv("XDG_CACHE_HOME");
  if (xdg && *xdg == '/') return std::string(xdg) + "/catgs";  // the spec: relative values are ignored
  const char* home = std::getenv("HOME");
  if (home && *home) return std::string(home) + "/.cache/catgs";
  return "";
}

void write_scene_cache(const GaussianModel& model, const std::string& scene_path, const std::string& cache_path,
                       int threads) {
  fm::validate_lod(model.lod, model.size());
  CacheHeader h = layout(model.size(), model.sh_degree, !model.lod.empty());
  h.source = source_stamp(scene_path);
  const std::vector<fm::ChunkBounds> chunks = chunk_bounds_of(model);
  write_replacing(cache_path, h.file_size, [&](int fd) {
    const std::vector<Block> bl = blocks(h);
    std::vector<uint64_t> hashes(bl.size());
    run_blocks(bl.size(), threads, [&](uint64_t k) {
      const Block& b = bl[k];
      const uint64_t bytes = b.end - b.begin;
      const void* src = nullptr;
      std::vector<uint16_t> half;
      if (b.section == kShHalf) {  // rounded a block at a time: no second SH array in memory
        half.resize(bytes / 2);
        const float* sh = model.sh.data() + b.begin / 2;
        for (std::size_t i = 0; i < half.size(); ++i) half[i] = fm::half_bits(sh[i]);
        src = half.data();
      } else if (b.section == kChunks) {
        src = reinterpret_cast<const char*>(chunks.data()) + b.begin;
      } else if (b.section == kLod) {
        src = reinterpret_cast<const char*>(model.lod.data()) + b.begin;
      } else {
        src = static_cast<const char*>(float_section(model, b.section)) + b.begin;
      }
      hashes[b.slot] = XXH3_64bits(src, bytes);
      write_all(fd, src, bytes, h.offset[b.section] + b.begin, cache_path);
    });
    write_all(fd, hashes.data(), 8 * hashes.size(), h.hashes_offset, cache_path);
    h.hashes_hash = XXH3_64bits(hashes.data(), 8 * hashes.size());
    h.header_hash = header_hash(h);
    std::vector<char> page(kAlign, 0);
    std::memcpy(page.data(), &h, sizeof h);
    write_all(fd, page.data(), page.size(), 0, cache_path);
  });
}

void reseal_scene_cache(std::string& bytes, const std::string& scene_path) {
  CacheHeader h{};
  if (bytes.size() < sizeof h) return;
  std::memcpy(&h, bytes.data(), sizeof h);
  h.source = source_stamp(scene_path);
  const uint64_t size = bytes.size();
  auto inside = [size](uint64_t offset, uint64_t n) { return offset <= size && n <= size - offset; };
  const uint64_t table_slots =
      inside(h.hashes_offset, 0) ? std::min(h.hash_count, (size - h.hashes_offset) / 8) : uint64_t{0};
  uint64_t slot = 0;
  for (int s = 0; s < kSections && slot < table_slots; ++s)
    for (uint64_t b = 0; b < h.bytes[s] && slot < table_slots; b += kCacheBlockBytes, ++slot) {
      const uint64_t n = std::min(h.bytes[s] - b, kCacheBlockBytes);
      if (!inside(h.offset[s], b) || !inside(h.offset[s] + b, n)) continue;
      const uint64_t hash = XXH3_64bits(bytes.data() + h.offset[s] + b, n);
      std::memcpy(&bytes[h.hashes_offset + 8 * slot], &hash, 8);
    }
  if (inside(h.hashes_offset, 8 * table_slots) && table_slots == h.hash_count)
    h.hashes_hash = XXH3_64bits(bytes.data() + h.hashes_offset, 8 * h.hash_count);
  h.header_hash = header_hash(h);
  std::memcpy(bytes.data(), &h, sizeof h);
}

struct SceneCache::Impl {
  std::string path, scene;
  CacheHeader h{};
  ply::MappedFile file;
  const uint8_t* section(int s) const { return file.data() + h.offset[s]; }
};

SceneCache::SceneCache(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
SceneCache::~SceneCache() = default;
uint64_t SceneCache::size() const { return impl_->h.gaussians; }
int SceneCache::sh_degree() const { return static_cast<int>(impl_->h.sh_degree); }
const uint16_t* SceneCache::sh_half() const { return reinterpret_cast<const uint16_t*>(impl_->section(kShHalf)); }
const fm::ChunkBounds* SceneCache::chunks() const {
  return reinterpret_cast<const fm::ChunkBounds*>(impl_->section(kChunks));
}

std::unique_ptr<SceneCache> SceneCache::open(const std::string& cache_path, const std::string& scene_path) {
  auto reject = [&](const std::string& why) { return SceneCacheRejected(cache_path, why); };
  struct stat st {};
  if (::stat(cache_path.c_str(), &st) != 0) throw reject("no cache file");
  const auto size = static_cast<uint64_t>(st.st_size);
  auto impl = std::make_unique<Impl>();
  impl->path = cache_path;
  impl->scene = scene_path;
  if (size < sizeof(CacheHeader)) throw reject("truncated: " + std::to_string(size) + " bytes, shorter than a header");
  {
    const int fd = ::open(cache_path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) throw reject(std::string("cannot open: ") + std::strerror(errno));
    const ssize_t got = ::pread(fd, &impl->h, sizeof impl->h, 0);
    ::close(fd);
    if (got != static_cast<ssize_t>(sizeof impl->h)) throw reject("cannot read its header");
  }
  const CacheHeader& h = impl->h;
  if (std::memcmp(h.magic, kMagic, sizeof kMagic) != 0) throw reject("not a scene cache (no CATGSCAC magic)");
  if (h.endian != kEndian) throw reject("written on a machine of another byte order");
  if (h.version != kSceneCacheVersion)
    throw reject("cache version " + std::to_string(h.version) + ", this build reads version " +
                 std::to_string(kSceneCacheVersion));
  if (header_hash(h) != h.header_hash) throw reject("header checksum mismatch");
  // A count no file of this size can hold is refused before the layout's arithmetic uses it
  // (every Gaussian takes over 4 bytes), so those products stay far below 2^64.
  if (h.gaussians > size / 4) throw reject("Gaussian count " + std::to_string(h.gaussians) + " larger than the file");
  // The layout must be the one this build would write for that many Gaussians.
  const CacheHeader expect =
      layout(h.gaussians, static_cast<int>(std::min<uint32_t>(h.sh_degree, kMaxShDegree)), h.lod_nodes != 0);
  if (h.sh_degree > static_cast<uint32_t>(kMaxShDegree) || h.chunk_size != expect.chunk_size ||
      h.block_bytes != expect.block_bytes || h.lod_nodes != expect.lod_nodes ||
      h.hashes_offset != expect.hashes_offset || h.hash_count != expect.hash_count || h.file_size != expect.file_size ||
      std::memcmp(h.offset, expect.offset, sizeof h.offset) != 0 ||
      std::memcmp(h.bytes, expect.bytes, sizeof h.bytes) != 0)
    throw reject("section layout does not match its Gaussian count");
  if (size != h.file_size)
    throw reject("truncated or extended: " + std::to_string(size) + " bytes, the header says " +
                 std::to_string(h.file_size));
  SourceStamp now;
  try {
    now = source_stamp(scene_path);
  } catch (const std::exception& e) {
    throw reject(std::string("cannot check the source: ") + e.what());
  }
  if (now.size != h.source.size || now.mtime_ns != h.source.mtime_ns || now.head_hash != h.source.head_hash)
    throw reject(now.size != h.source.size ? "the source changed (size " + std::to_string(h.source.size) + " -> " +
                                                 std::to_string(now.size) + " bytes)"
                 : now.mtime_ns != h.source.mtime_ns ? std::string("the source changed (modification time)")
                                                     : std::string("the source changed (its header)"));
  try {
    impl->file = ply::MappedFile(cache_path, size);
  } catch (const std::exception& e) {
    throw reject(e.what());
  }
  const auto* table = reinterpret_cast<const uint64_t*>(impl->file.data() + h.hashes_offset);
  if (XXH3_64bits(table, 8 * h.hash_count) != h.hashes_hash) throw reject("block hash table checksum mismatch");
  return std::unique_ptr<SceneCache>(new SceneCache(std::move(impl)));
}

GaussianModel SceneCache::read_model(int threads, const LoadProgress& progress) const {
  const Impl& c = *impl_;
  GaussianModel m;
  m.sh_degree = static_cast<int>(c.h.sh_degree);
  m.resize(c.h.gaussians);
  m.lod.resize(c.h.lod_nodes);
  m.name = scene_name(c.scene);
  const std::vector<Block> bl = blocks(c.h);
  const auto* table = reinterpret_cast<const uint64_t*>(c.file.data() + c.h.hashes_offset);
  const uint64_t n = c.h.gaussians;
  run_blocks(
      bl.size(), threads,
      [&](uint64_t k) {
        const Block& b = bl[k];
        const uint8_t* src = c.section(b.section) + b.begin;
        if (XXH3_64bits(src, b.end - b.begin) != table[b.slot])
          throw SceneCacheRejected(c.path, std::string("checksum mismatch in section ") + kSectionNames[b.section] +
                                               " at byte " + std::to_string(b.begin));
        if (void* dst = b.section == kLod ? static_cast<void*>(m.lod.data()) : float_section(m, b.section)) {
          std::memcpy(static_cast<char*>(dst) + b.begin, src, b.end - b.begin);
          if (b.section != kLod) check_finite(m, b, c.path);
        }
        c.file.release(c.h.offset[b.section] + b.begin, c.h.offset[b.section] + b.end);
      },
      [&](uint64_t done) {
        if (progress && done < bl.size()) progress(n * done / bl.size(), n);
      });
  if (progress) progress(n, n);
  try {
    fm::validate_lod(m.lod, m.size());
  } catch (const std::exception& e) {
    throw SceneCacheRejected(c.path, e.what());
  }
  return m;
}

bool SceneCache::has_lod() const { return impl_->h.lod_nodes != 0; }

GaussianModel load_lod_file(const std::string& lod_path, const std::string& scene_path, int threads,
                            const LoadProgress& progress) {
  {
    std::vector<uint8_t> head(8, 0);
    std::FILE* f = std::fopen(lod_path.c_str(), "rb");
    if (f) {
      head.resize(std::fread(head.data(), 1, head.size(), f));
      std::fclose(f);
    }
    if (looks_like_compact(head)) return read_compact_lod(lod_path, scene_path, threads, progress);
  }
  const auto cache = SceneCache::open(lod_path, scene_path);
  if (!cache->has_lod())
    throw SceneCacheRejected(lod_path, "a scene cache without a level of detail (write one with catgs-scene lod)");
  return cache->read_model(threads, progress);
}

GaussianModel load_scene_cached(const std::string& path, const CachedLoadOptions& options, const LoadProgress& progress,
                                CachedLoadReport* report) {
  CachedLoadReport local;
  CachedLoadReport& r = report ? *report : local;
  r = CachedLoadReport{};
  if (options.mode == SceneCacheMode::off) return load_scene(path, options.load, progress);
  auto log = [&](const std::string& line) {
    if (options.log) options.log(line);
  };
  const std::string cache_path = options.cache_path.empty() ? scene_cache_path(path) : options.cache_path;
  try {
    const auto cache = SceneCache::open(cache_path, path);
    GaussianModel m = cache->read_model(options.load.threads, progress);
    r.from_cache = true;
    log("scene cache: " + cache_path + ": used");
    return m;
  } catch (const SceneCacheRejected& e) {
    r.why = e.what();
  }
  log("scene cache: " + r.why + "; reading the scene");
  GaussianModel m = load_scene(path, options.load, progress);
  if (options.mode == SceneCacheMode::write) {
    try {
      write_scene_cache(m, path, cache_path, options.load.threads);
      r.written = true;
      log("scene cache: wrote " + cache_path);
    } catch (const std::exception& e) {
      log(std::string("scene cache: not written (") + e.what() + "); the load goes on");
    }
  }
  return m;
}

}  // namespace catgs
