#include "engine/sample_set.h"

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <numeric>

#include "runtime/core/body_parts.h"

namespace poseforest::engine {

namespace {
/// New storage for a SampleSet's per-sample columns, filled in a new order (StartTree: by node;
/// ApplySplits: left, then right, per node) and then swapped in.
struct SampleColumns {
  std::vector<uint32_t> frame;
  std::vector<int16_t> x, y;
  std::vector<float> scale;
  std::vector<uint8_t> part;
  explicit SampleColumns(size_t n) : frame(n), x(n), y(n), scale(n), part(n) {}
  void Set(uint64_t o, uint32_t f, int16_t px, int16_t py, float s, uint8_t p) {
    frame[o] = f;
    x[o] = px;
    y[o] = py;
    scale[o] = s;
    part[o] = p;
  }
  void SwapWith(std::vector<uint32_t>& f, std::vector<int16_t>& px, std::vector<int16_t>& py,
                std::vector<float>& s, std::vector<uint8_t>& p) {
    f.swap(frame);
    px.swap(x);
    py.swap(y);
    s.swap(scale);
    p.swap(part);
  }
};
}  // namespace

std::vector<PixelSample> SamplePixels(const LabelledFrame& frame, int count, double balance,
                                      const core::CounterRng& rng) {
  POSEFOREST_CHECK(frame.depth.width == frame.labels.width && frame.depth.height == frame.labels.height);
  // Body pixels per part, in row-major order.
  std::vector<std::vector<uint32_t>> by_part(core::kNumParts);
  const size_t n = frame.depth.pixels.size();
  for (size_t i = 0; i < n; ++i) {
    const uint8_t l = frame.labels.pixels[i];
    if (l < core::kNumParts && frame.depth.pixels[i] != 0) by_part[l].push_back(uint32_t(i));
  }
  // Quotas: weight n_c^(1-balance), water-filled so no part gets more than it has.
  std::vector<int64_t> quota(core::kNumParts, 0);
  int64_t left = count;
  std::vector<int> open;
  for (int c = 0; c < core::kNumParts; ++c)
    if (!by_part[c].empty()) open.push_back(c);
  while (left > 0 && !open.empty()) {
    double total_w = 0;
    for (int c : open) total_w += std::pow(double(by_part[c].size()), 1.0 - balance);
    std::vector<int> still_open;
    int64_t given = 0;
    for (int c : open) {
      const int64_t room = int64_t(by_part[c].size()) - quota[c];
      const double share = double(left) * std::pow(double(by_part[c].size()), 1.0 - balance) / total_w;
      int64_t q = std::min<int64_t>(room, int64_t(std::floor(share)));
      quota[c] += q;
      given += q;
      if (quota[c] < int64_t(by_part[c].size())) still_open.push_back(c);
    }
    left -= given;
    if (given == 0) {
      // Fractional remainders: one more pixel each to the open parts in part order.
      for (int c : still_open) {
        if (left == 0) break;
        ++quota[c];
        --left;
      }
      still_open.erase(std::remove_if(still_open.begin(), still_open.end(),
                                      [&](int c) { return quota[c] >= int64_t(by_part[c].size()); }),
                       still_open.end());
    }
    open.swap(still_open);
  }
  // Partial Fisher-Yates per part; draw index = part * 2^32 + step, so parts are independent.
  std::vector<PixelSample> out;
  out.reserve(size_t(count));
  std::vector<uint32_t> chosen;
  for (int c = 0; c < core::kNumParts; ++c) {
    auto& pix = by_part[c];
    const auto q = size_t(quota[c]);
    for (size_t k = 0; k < q; ++k) {
      const size_t j = k + rng.UniformInt((uint64_t(c) << 32) + k, uint32_t(pix.size() - k));
      std::swap(pix[k], pix[j]);
      chosen.push_back(pix[k]);
    }
  }
  std::sort(chosen.begin(), chosen.end());
  for (uint32_t i : chosen) {
    const int x = int(i % uint32_t(frame.depth.width)), y = int(i / uint32_t(frame.depth.width));
    out.push_back({x, y, frame.labels.pixels[i]});
  }
  return out;
}

CompactFrame CompactFrame::Of(const core::DepthImage& depth, uint16_t background_mm) {
  POSEFOREST_CHECK(depth.width >= 0 && depth.height >= 0 && depth.width <= 32767 && depth.height <= 32767 &&
                   depth.pixels.size() == size_t(depth.width) * size_t(depth.height));
  CompactFrame f;
  f.width = depth.width;
  f.height = depth.height;
  f.rows.resize(size_t(depth.height));
  // A pixel reads background_mm when its depth is 0 or background_mm itself.
  auto differs = [&](uint16_t d) { return d != 0 && d != background_mm; };
  for (int y = 0; y < depth.height; ++y) {
    const uint16_t* row = depth.data() + size_t(y) * size_t(depth.width);
    int lo = 0, hi = depth.width;
    while (lo < hi && !differs(row[lo])) ++lo;
    while (hi > lo && !differs(row[hi - 1])) --hi;
    if (lo == hi) continue;  // the whole row reads background_mm
    Row& r = f.rows[size_t(y)];
    r.start = uint32_t(f.pixels.size());
    r.lo = uint16_t(lo);
    r.len = uint16_t(hi - lo);
    for (int x = lo; x < hi; ++x) f.pixels.push_back(row[x] != 0 ? row[x] : background_mm);
  }
  return f;
}

void SampleSet::Reserve(size_t frames, size_t pixels, size_t samples, size_t rows) {
  frames_.reserve(frames_.size() + frames);
  probe_.reserve(probe_.size() + pixels + 32);
  rows_.reserve(rows_.size() + rows);
  frame_.reserve(frame_.size() + samples);
  x_.reserve(x_.size() + samples);
  y_.reserve(y_.size() + samples);
  scale_.reserve(scale_.size() + samples);
  part_.reserve(part_.size() + samples);
}

void SampleSet::AddFrame(uint64_t frame_index, const CompactFrame& frame, std::span<const PixelSample> pixels,
                         const core::FeatureConstants& c) {
  POSEFOREST_CHECK(frames_.empty() || frame_index > frames_.back().index);
  AddSamples(AddFrameOnly(frame_index, frame, c), pixels, c);
}

void SampleSet::AddFrame(uint64_t frame_index, const core::DepthImage& depth,
                         std::span<const PixelSample> pixels, const core::FeatureConstants& c) {
  POSEFOREST_CHECK(frames_.empty() || frame_index > frames_.back().index);
  AddSamples(AddFrameOnly(frame_index, depth, c), depth, pixels, c);
}

uint32_t SampleSet::AddFrameOnly(uint64_t frame_index, const core::DepthImage& depth,
                                 const core::FeatureConstants& c) {
  return AddFrameOnly(frame_index, CompactFrame::Of(depth, c.background_mm), c);
}

uint32_t SampleSet::AddFrameOnly(uint64_t frame_index, const CompactFrame& frame,
                                 const core::FeatureConstants& c) {
  POSEFOREST_CHECK(frames_.empty() || (background_mm_ == c.background_mm && edge_ == c.edge));
  POSEFOREST_CHECK(frame.width <= 32767 && frame.height <= 32767 &&
                   frame.rows.size() == size_t(frame.height) &&
                   size_t(frame.width) * size_t(frame.height) < (size_t(1) << 24));
  constexpr size_t kPad = 32;
  const size_t offset = probe_.empty() ? 0 : probe_.size() - kPad;
  // 32-bit gather indices: a shard holds at most 2^31 span pixels, and 2^31 / 8 rows.
  POSEFOREST_CHECK_MSG(offset + frame.pixels.size() < (size_t(1) << 31) &&
                           rows_.size() + frame.rows.size() < (size_t(1) << 28),
                       "shard too large: split the frames over more shards");
  background_mm_ = c.background_mm;
  edge_ = c.edge;
  if (!frames_.empty() && (frames_[0].width != frame.width || frames_[0].height != frame.height))
    uniform_size_ = false;
  frames_.push_back({frame_index, uint32_t(rows_.size()), frame.width, frame.height});
  for (CompactFrame::Row r : frame.rows) {
    POSEFOREST_CHECK(size_t(r.start) + r.len <= frame.pixels.size() &&
                     size_t(r.lo) + r.len <= size_t(frame.width));
    r.start += uint32_t(offset);
    rows_.push_back(r);
  }
  probe_.resize(offset + frame.pixels.size() + kPad, c.background_mm);
  std::copy(frame.pixels.begin(), frame.pixels.end(), probe_.begin() + ptrdiff_t(offset));
  return uint32_t(frames_.size() - 1);
}

void SampleSet::AddSamples(uint32_t local, std::span<const PixelSample> pixels,
                           const core::FeatureConstants& c) {
  POSEFOREST_CHECK(local < frames_.size());
  for (const PixelSample& p : pixels) {
    // A body pixel (depth > 0) reads its depth: in its row's span unless it equals background_mm,
    // which is then what Probe returns.
    const int32_t d = Probe(local, p.x, p.y, c.background_mm);
    POSEFOREST_CHECK(p.x >= 0 && p.x < frames_[local].width && p.y >= 0 && p.y < frames_[local].height &&
                     d > 0);
    frame_.push_back(local);
    x_.push_back(int16_t(p.x));
    y_.push_back(int16_t(p.y));
    scale_.push_back(core::PixelScale(uint16_t(d), c.offset_unit));
    part_.push_back(p.part);
  }
}

void SampleSet::AddSamples(uint32_t local, const core::DepthImage& depth, std::span<const PixelSample> pixels,
                           const core::FeatureConstants& c) {
  POSEFOREST_CHECK(local < frames_.size() && frames_[local].width == depth.width &&
                   frames_[local].height == depth.height);
  for (const PixelSample& p : pixels) POSEFOREST_CHECK(depth.at(p.x, p.y) != 0);
  AddSamples(local, pixels, c);
}

void SampleSet::ClearSamples() {
  frame_.clear();
  x_.clear();
  y_.clear();
  scale_.clear();
  part_.clear();
  ranges_.clear();
}

void SampleSet::StartTree(uint32_t root) {
  ranges_.clear();
  if (!x_.empty()) ranges_.push_back({root, 0, x_.size()});
}

void SampleSet::StartTree(std::span<const uint32_t> node_of_sample) {
  POSEFOREST_CHECK(node_of_sample.size() == x_.size());
  // A stable counting sort by node.
  std::vector<uint32_t> nodes(node_of_sample.begin(), node_of_sample.end());
  std::sort(nodes.begin(), nodes.end());
  nodes.erase(std::unique(nodes.begin(), nodes.end()), nodes.end());
  std::vector<uint64_t> start(nodes.size() + 1, 0);
  for (uint32_t n : node_of_sample)
    ++start[size_t(std::lower_bound(nodes.begin(), nodes.end(), n) - nodes.begin()) + 1];
  for (size_t k = 0; k < nodes.size(); ++k) start[k + 1] += start[k];
  ranges_.clear();
  for (size_t k = 0; k < nodes.size(); ++k) ranges_.push_back({nodes[k], start[k], start[k + 1]});
  SampleColumns out(x_.size());
  for (size_t i = 0; i < x_.size(); ++i) {
    const size_t k = size_t(std::lower_bound(nodes.begin(), nodes.end(), node_of_sample[i]) - nodes.begin());
    const uint64_t o = start[k]++;
    out.Set(o, frame_[i], x_[i], y_[i], scale_[i], part_[i]);
  }
  out.SwapWith(frame_, x_, y_, scale_, part_);
}

NodeRange SampleSet::RangeOf(uint32_t node) const {
  auto it = std::lower_bound(ranges_.begin(), ranges_.end(), node,
                             [](const NodeRange& r, uint32_t n) { return r.node < n; });
  if (it != ranges_.end() && it->node == node) return *it;
  return {node, 0, 0};
}

uint64_t SampleSet::uid(size_t i) const {
  const FrameInfo& f = frames_[frame_[i]];
  return (f.index << 24) | uint64_t(uint32_t(y_[i]) * uint32_t(f.width) + uint32_t(x_[i]));
}

void SampleSet::CountParts(const NodeRange& r, int num_parts, uint64_t* counts) const {
  std::fill(counts, counts + num_parts, 0);
  for (uint64_t i = r.begin; i < r.end; ++i) {
    POSEFOREST_CHECK(part_[i] < num_parts);
    ++counts[part_[i]];
  }
}

void SampleSet::ApplySplits(std::span<const Split> splits, const core::FeatureConstants& c, int threads) {
  // Match each range with its split (both sorted by node).
  std::vector<const Split*> of_range(ranges_.size(), nullptr);
  for (size_t r = 0, s = 0; r < ranges_.size(); ++r) {
    while (s < splits.size() && splits[s].node < ranges_[r].node) ++s;
    if (s < splits.size() && splits[s].node == ranges_[r].node) of_range[r] = &splits[s];
  }
  std::vector<uint64_t> out_begin(ranges_.size() + 1, 0);
  for (size_t r = 0; r < ranges_.size(); ++r)
    out_begin[r + 1] = out_begin[r] + (of_range[r] ? ranges_[r].end - ranges_[r].begin : 0);
  const uint64_t kept = out_begin.back();
  SampleColumns out(kept);
  std::vector<uint64_t> num_left(ranges_.size(), 0);
  const auto nr = int64_t(ranges_.size());
  uint64_t largest = 0;
  for (const NodeRange& r : ranges_) largest = std::max(largest, r.end - r.begin);
  // Scratch allocated before the region, so nothing inside can throw.
  std::vector<std::vector<uint8_t>> scratch(static_cast<size_t>(std::max(1, threads)),
                                            std::vector<uint8_t>(largest));
#pragma omp parallel num_threads(threads)
  {
    std::vector<uint8_t>& goes_left = scratch[size_t(omp_get_thread_num())];
#pragma omp for schedule(dynamic, 1)
    for (int64_t r = 0; r < nr; ++r) {
      const Split* s = of_range[size_t(r)];
      if (!s) continue;
      const NodeRange& range = ranges_[size_t(r)];
      uint64_t nl = 0;
      for (uint64_t i = range.begin; i < range.end; ++i) {
        const int32_t f = Response(i, s->offsets, c.background_mm);
        const bool left = f <= s->cut;
        goes_left[i - range.begin] = left;
        nl += left;
      }
      uint64_t li = out_begin[size_t(r)], ri = li + nl;
      for (uint64_t i = range.begin; i < range.end; ++i) {
        const uint64_t o = goes_left[i - range.begin] ? li++ : ri++;
        out.Set(o, frame_[i], x_[i], y_[i], scale_[i], part_[i]);
      }
      num_left[size_t(r)] = nl;
    }
  }
  std::vector<NodeRange> ranges;
  for (size_t r = 0; r < ranges_.size(); ++r) {
    const Split* s = of_range[r];
    if (!s) continue;
    const uint64_t b = out_begin[r], m = b + num_left[r], e = out_begin[r + 1];
    if (m > b) ranges.push_back({s->left_child, b, m});
    if (e > m) ranges.push_back({s->left_child + 1, m, e});
  }
  out.SwapWith(frame_, x_, y_, scale_, part_);
  ranges_.swap(ranges);
}

uint64_t SampleSet::MemoryBytes() const {
  uint64_t bytes = probe_.capacity() * sizeof(uint16_t) + rows_.capacity() * sizeof(CompactFrame::Row) +
                   frames_.capacity() * sizeof(FrameInfo);
  bytes += frame_.capacity() * 4 + x_.capacity() * 2 + y_.capacity() * 2 + scale_.capacity() * 4 +
           part_.capacity() + ranges_.capacity() * sizeof(NodeRange);
  return bytes;
}

}  // namespace poseforest::engine
