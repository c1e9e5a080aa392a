#include "runtime/classifier.h"

#include "runtime/classifier_internal.h"

// How the classifier is fast (figures: bench/classify):
//  - Phase 1 (vectorized, on the calling thread) lists the foreground pixels compactly with
//    PixelScale computed once, and writes a copy of the depth in which 0 already reads as the
//    background constant (so a probe needs only a bounds test). Phase 2, scheduled
//    dynamically over the OpenMP team in chunks of kChunk foreground pixels, walks each tree
//    in turn over a chunk (the top of the tree stays in L1/L2), then sums leaf rows and takes
//    the argmax while the leaf indices are still in L1. The per-pixel sums go out from there:
//    to the compact foreground array (want_foreground_distributions: the row of foreground
//    pixel k at k * stride, no per-frame clearing) and/or the dense W*H*stride one.
//  - A tree walk keeps many independent traversals in flight. AVX-512: 16 pixels per vector,
//    two vectors interleaved to hide load latency; a lane whose pixel reached a leaf is
//    refilled with the next pixel at once (compress/expand), so no lane idles while deeper
//    siblings finish; nodes come from 16 plain loads plus a transpose, probes from two
//    16-lane gathers. AVX2 (machines without AVX-512): the same with 8 lanes per vector and
//    a permutation table for the refill. Portable: 32 lanes in lockstep, the float arithmetic
//    of all lanes in one auto-vectorized loop, then probe reads and branch-free child
//    selection per lane.
// Every path evaluates exactly core::FeatureResponse (same float operations in the same order,
// no FMA: the project builds with -ffp-contract=off), so results are bit-identical to a naive
// evaluator whatever the path or the thread count.

#include <omp.h>

#include <algorithm>
#include <bit>
#include <cstring>

#include "runtime/classifier_kernels.h"

#if defined(POSEFOREST_CLASSIFIER_AVX512) || defined(POSEFOREST_CLASSIFIER_AVX2)
#include <immintrin.h>
#endif

namespace poseforest::runtime {
namespace {

using detail::kChunk;
using detail::kPad;

/// Per-call working data, reused across calls on the same thread (no allocation per frame).
struct Scratch {
  /// Depth with 0 replaced by background_mm, plus kPad entries of background_mm: a 32-bit
  /// gather at the last pixel stays inside, and the portable kernel reads probe[w * h] for
  /// probes off the image.
  std::vector<uint16_t> probe;
  /// Per foreground pixel, row-major, kPad entries of slack: x - 32768 and y - 32768
  /// (RoundOffset's bias folded in: x + RoundOffset(v) == (x - 32768) + int(v + 32768.5f)),
  /// PixelScale, and the linear pixel index.
  std::vector<int32_t> xb, yb;
  std::vector<float> scale;
  std::vector<uint32_t> pixel;
  /// Per OpenMP thread, leaf index per (tree, pixel of the current chunk):
  /// leaves[(thread * trees + t) * kChunk + i].
  std::vector<uint32_t> leaves;
};


/// Appends foreground pixel (x, y) of depth d to the lists of ListRowPortable/ListRowStrided.
inline void AppendPixel(int x, int y, uint16_t d, int width, float unit_mm, int32_t* xb, int32_t* yb, float* scale,
                        uint32_t* pixel, int* count) {
  xb[*count] = x - 32768;
  yb[*count] = y - 32768;
  scale[*count] = unit_mm / float(d);  // == core::PixelScale(d, offset_unit)
  pixel[*count] = uint32_t(size_t(y) * size_t(width) + size_t(x));
  ++*count;
}

/// One image row: copies depth to `probe` with 0 replaced by `background`, and appends the
/// row's foreground pixels to the lists (x - 32768, y - 32768, PixelScale, linear index).
/// Returns how many were appended.
int ListRowPortable(const uint16_t* depth, int width, int y, uint16_t background, float unit_mm,
                    uint16_t* probe, int32_t* xb, int32_t* yb, float* scale, uint32_t* pixel) {
  int count = 0;
  for (int x = 0; x < width; ++x) {
    const uint16_t d = depth[x];
    probe[x] = d != 0 ? d : background;
    if (d == 0) continue;
    AppendPixel(x, y, d, width, unit_mm, xb, yb, scale, pixel, &count);
  }
  return count;
}

/// One image row of a subsampled grid (ClassifyOptions::pixel_stride > 1): copies depth to
/// `probe` as ListRowPortable, and lists only the row's foreground pixels with x % stride == 0
/// when `listed` (a grid row). Returns how many were appended.
int ListRowStrided(const uint16_t* depth, int width, int y, int stride, bool listed, uint16_t background,
                   float unit_mm, uint16_t* probe, int32_t* xb, int32_t* yb, float* scale, uint32_t* pixel) {
  for (int x = 0; x < width; ++x) probe[x] = depth[x] != 0 ? depth[x] : background;
  if (!listed) return 0;
  int count = 0;
  for (int x = 0; x < width; x += stride) {
    const uint16_t d = depth[x];
    if (d == 0) continue;
    AppendPixel(x, y, d, width, unit_mm, xb, yb, scale, pixel, &count);
  }
  return count;
}

/// Labels of the pixels off the grid (pixel_stride > 1): a foreground pixel takes the label of
/// its grid pixel (x - x % s, y - y % s), which is kBackgroundLabel when that one is not
/// foreground. Grid pixels and background pixels keep theirs.
void FillOffGridLabels(const core::DepthImage& depth, int stride, core::LabelImage* labels) {
  const int width = depth.width, height = depth.height;
  for (int y = 0; y < height; ++y) {
    const int ya = y - y % stride;
    const uint16_t* d = depth.pixels.data() + size_t(y) * size_t(width);
    uint8_t* row = labels->pixels.data() + size_t(y) * size_t(width);
    const uint8_t* grid = labels->pixels.data() + size_t(ya) * size_t(width);
    for (int x0 = 0; x0 < width; x0 += stride) {
      const uint8_t label = grid[x0];
      const int x1 = std::min(width, x0 + stride);
      for (int x = ya == y ? x0 + 1 : x0; x < x1; ++x)
        if (d[x] != 0) row[x] = label;
    }
  }
}

#ifdef POSEFOREST_CLASSIFIER_AVX512
// GCC 12's shift/convert intrinsics start from _mm512_undefined_*(), which its -Wuninitialized
// wrongly reports when inlined (GCC bug 105593, fixed in 12.3/13).
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wuninitialized"
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"

/// ListRowPortable, 16 pixels at a time (the lists need 16 entries of slack after the row's
/// last foreground pixel: full-vector stores of compressed data).
int ListRowAvx512(const uint16_t* depth, int width, int y, uint16_t background, float unit_mm,
                  uint16_t* probe, int32_t* xb, int32_t* yb, float* scale, uint32_t* pixel) {
  const __m256i bg = _mm256_set1_epi16(short(background));
  const __m512i iota = _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
  const __m512i vyb = _mm512_set1_epi32(y - 32768);
  const __m512 vunit = _mm512_set1_ps(unit_mm);
  const uint32_t row_start = uint32_t(size_t(y) * size_t(width));
  int count = 0;
  for (int x = 0; x < width; x += 16) {
    const __mmask16 in = width - x >= 16 ? __mmask16(0xFFFF) : __mmask16((1u << (width - x)) - 1u);
    const __m256i d = _mm256_maskz_loadu_epi16(in, depth + x);
    const __mmask16 fg = _mm256_test_epi16_mask(d, d);
    _mm256_mask_storeu_epi16(probe + x, in, _mm256_mask_blend_epi16(fg, bg, d));
    if (fg == 0) continue;
    const __m512i xs = _mm512_add_epi32(_mm512_set1_epi32(x), iota);
    // Same division as core::PixelScale (IEEE, correctly rounded in both).
    const __m512 sc = _mm512_div_ps(vunit, _mm512_cvtepi32_ps(_mm512_cvtepu16_epi32(d)));
    _mm512_storeu_si512(xb + count,
                        _mm512_maskz_compress_epi32(fg, _mm512_sub_epi32(xs, _mm512_set1_epi32(32768))));
    _mm512_storeu_si512(yb + count, vyb);
    _mm512_storeu_ps(scale + count, _mm512_maskz_compress_ps(fg, sc));
    _mm512_storeu_si512(pixel + count, _mm512_maskz_compress_epi32(
                                           fg, _mm512_add_epi32(xs, _mm512_set1_epi32(int(row_start)))));
    count += std::popcount(unsigned(fg));
  }
  return count;
}
#pragma GCC diagnostic pop
#endif  // POSEFOREST_CLASSIFIER_AVX512

/// What every chunk of phase 2 shares, set up before the parallel region.
struct ChunkWork {
  const core::Forest* forest = nullptr;
  const Scratch* s = nullptr;
  Classification* out = nullptr;
  int width = 0, height = 0, total = 0, num_trees = 0, stride = 0;
  uint16_t background = 0;
  bool use_avx512 = false, use_avx2 = false, want_foreground = false;
  uint32_t* fg_leaves = nullptr;  ///< the compact leaves output, or null
};

/// The outputs' sizes and fields for `depth` (want_distributions: dense sums sized; the compact
/// foreground outputs emptied, filled later).
void ShapeOutput(const core::Forest& forest, const core::DepthImage& depth, const ClassifyOptions& options,
                 Classification* out) {
  const int width = depth.width, height = depth.height;
  const size_t n = size_t(width) * size_t(height);
  const int stride = forest.leaf_stride();
  out->width = width;
  out->height = height;
  out->num_parts = forest.num_parts;
  out->num_trees = int(forest.trees.size());
  out->stride = stride;
  out->pixel_stride = std::max(1, options.pixel_stride);
  out->labels.width = width;
  out->labels.height = height;
  out->labels.pixels.resize(n);
  if (options.want_distributions) {
    out->sums.resize(n * size_t(stride));
  } else {
    out->sums.clear();
  }
  out->foreground.clear();
  out->foreground_sums.clear();
  out->foreground_leaves.clear();
}

/// Phase 1's foreground list: every row's depth into s.probe and its foreground pixels
/// (of the grid, pixel_stride > 1) appended to s.xb, s.yb, s.scale, s.pixel. Returns how many.
int ListForeground(const core::DepthImage& depth, int pixel_stride, uint16_t background, float unit_mm,
                   bool use_avx512, Scratch& s) {
  const int width = depth.width, height = depth.height;
  int total = 0;
  for (int y = 0; y < height; ++y) {
    const size_t row = size_t(y) * size_t(width);
    const size_t i = size_t(total);
    if (pixel_stride > 1) {
      total +=
          ListRowStrided(depth.pixels.data() + row, width, y, pixel_stride, y % pixel_stride == 0, background,
                         unit_mm, s.probe.data() + row, &s.xb[i], &s.yb[i], &s.scale[i], &s.pixel[i]);
      continue;
    }
#ifdef POSEFOREST_CLASSIFIER_AVX512
    if (use_avx512) {
      total += ListRowAvx512(depth.pixels.data() + row, width, y, background, unit_mm, s.probe.data() + row,
                             &s.xb[i], &s.yb[i], &s.scale[i], &s.pixel[i]);
      continue;
    }
#endif
    total += ListRowPortable(depth.pixels.data() + row, width, y, background, unit_mm, s.probe.data() + row,
                             &s.xb[i], &s.yb[i], &s.scale[i], &s.pixel[i]);
  }
  (void)use_avx512;
  return total;
}

/// Phase 2 for chunk c of the foreground list: each tree in turn over the chunk (leaf indices
/// into `leaves`, this thread's kChunk x trees block), then sums and argmax.
inline void ClassifyChunk(const ChunkWork& w, int c, uint32_t* leaves) {
  const core::Forest& forest = *w.forest;
  const Scratch& s = *w.s;
  Classification* out = w.out;
  const int num_trees = w.num_trees;
  const int begin = c * kChunk, count = std::min(w.total - begin, kChunk);
  detail::FrameView view;
  view.width = w.width;
  view.height = w.height;
  view.background_mm = w.background;
  view.clamp = w.forest->constants.edge == core::ProbeEdge::kClamp;
  view.probe = s.probe.data();
  view.xb = s.xb.data() + begin;
  view.yb = s.yb.data() + begin;
  view.scale = s.scale.data() + begin;
  for (int t = 0; t < num_trees; ++t) {
    const core::Tree& tree = forest.trees[size_t(t)];
    uint32_t* tree_leaves = leaves + size_t(t) * size_t(kChunk);
    if (tree.nodes[0].is_leaf()) {
      std::fill(tree_leaves, tree_leaves + count, tree.nodes[0].leaf_index());
      continue;
    }
#ifdef POSEFOREST_CLASSIFIER_AVX512
    if (w.use_avx512) {
      if (view.clamp)
        detail::TraverseAvx512<detail::kAvx512Groups, true>(tree.nodes.data(), view, count, tree_leaves);
      else
        detail::TraverseAvx512<detail::kAvx512Groups, false>(tree.nodes.data(), view, count, tree_leaves);
      continue;
    }
#endif
#ifdef POSEFOREST_CLASSIFIER_AVX2
    if (w.use_avx2) {
      if (view.clamp)
        detail::TraverseAvx2<detail::kAvx2Groups, true>(tree.nodes.data(), view, count, tree_leaves);
      else
        detail::TraverseAvx2<detail::kAvx2Groups, false>(tree.nodes.data(), view, count, tree_leaves);
      continue;
    }
#endif
    if (view.clamp)
      detail::TraversePortable<detail::kPortableLanes, true>(tree.nodes.data(), view, count, tree_leaves);
    else
      detail::TraversePortable<detail::kPortableLanes, false>(tree.nodes.data(), view, count, tree_leaves);
  }
  if (w.fg_leaves) {
    // Pixel by pixel, so the output is written in order, one cache line after another.
    uint32_t* out_leaves = w.fg_leaves + size_t(begin) * size_t(num_trees);
    for (int i = 0; i < count; ++i)
      for (int t = 0; t < num_trees; ++t) *out_leaves++ = leaves[size_t(t) * size_t(kChunk) + size_t(i)];
  }
  const uint32_t* pixel = s.pixel.data() + begin;
  uint16_t* fg_sums = w.want_foreground ? out->foreground_sums.data() + size_t(begin) * size_t(w.stride) : nullptr;
#ifdef POSEFOREST_CLASSIFIER_AVX512
  if (w.use_avx512 && w.stride == 32) {
    detail::CombineAvx512Stride32(forest, leaves, kChunk, pixel, count, fg_sums, out);
    return;
  }
#endif
  detail::CombinePortable(forest, leaves, kChunk, pixel, count, fg_sums, out);
}

}  // namespace

namespace detail {

bool KernelAvailable(Kernel kernel) {
  switch (kernel) {
    case Kernel::kAuto:
    case Kernel::kPortable:
      return true;
    case Kernel::kAvx512:
#ifdef POSEFOREST_CLASSIFIER_AVX512
      return true;
#else
      return false;
#endif
    case Kernel::kAvx2:
#ifdef POSEFOREST_CLASSIFIER_AVX2
      return true;
#else
      return false;
#endif
  }
  return false;
}

void ClassifyWithKernel(const core::Forest& forest, const core::DepthImage& depth,
                        const ClassifyOptions& options, Kernel kernel, Classification* out) {
  if (kernel == Kernel::kAuto)
    kernel = KernelAvailable(Kernel::kAvx512) ? Kernel::kAvx512
             : KernelAvailable(Kernel::kAvx2) ? Kernel::kAvx2
                                              : Kernel::kPortable;
  if (!KernelAvailable(kernel)) kernel = Kernel::kPortable;

  const int width = depth.width, height = depth.height;
  const size_t n = size_t(width) * size_t(height);
  const int stride = forest.leaf_stride();
  const int num_trees = int(forest.trees.size());
  const uint16_t background = forest.constants.background_mm;
  const float unit_mm = forest.constants.offset_unit * 1000.0f;  // PixelScale's numerator

  ShapeOutput(forest, depth, options, out);
  const int pixel_stride = out->pixel_stride;
  if (n == 0) return;

  // All allocation happens here, before the parallel region: nothing inside can throw.
  // Per calling thread; a plain reference so that the OpenMP team shares the caller's copy.
  thread_local Scratch scratch;
  Scratch& s = scratch;
  s.probe.resize(n + kPad);
  s.xb.resize(n + kPad);
  s.yb.resize(n + kPad);
  s.scale.resize(n + kPad);
  s.pixel.resize(n + kPad);
  std::fill(s.probe.begin() + std::ptrdiff_t(n), s.probe.end(), background);
  const bool use_avx512 = kernel == Kernel::kAvx512;
  const bool use_avx2 = kernel == Kernel::kAvx2;

  // Phase 1, on the calling thread alone (~0.1 ms for a VGA frame): outputs cleared, the
  // probe copy, the foreground list. With the machine shared, every synchronisation of the
  // team can cost a scheduler slice; a barrier between two parallel phases measured worse.
  std::fill(out->labels.pixels.begin(), out->labels.pixels.end(), core::kBackgroundLabel);
  if (options.want_distributions) std::fill(out->sums.begin(), out->sums.end(), uint16_t(0));
  const int total = ListForeground(depth, pixel_stride, background, unit_mm, use_avx512, s);
  if (total == 0) return;  // (off the grid: no grid pixel is foreground, so no label either)
  const bool want_foreground = options.want_foreground_distributions;
  if (want_foreground) {
    // No clearing: every entry is written below.
    out->foreground.assign(s.pixel.begin(), s.pixel.begin() + total);
    out->foreground_sums.resize(size_t(total) * size_t(stride));
    if (options.want_foreground_leaves) out->foreground_leaves.resize(size_t(total) * size_t(num_trees));
  }

  const int num_chunks = (total + kChunk - 1) / kChunk;
  int threads = options.num_threads > 0 ? options.num_threads : omp_get_max_threads();
  threads = std::max(1, std::min(threads, num_chunks));
  s.leaves.resize(size_t(kChunk) * size_t(std::max(num_trees, 1)) * size_t(threads));
  ChunkWork work;
  work.forest = &forest;
  work.s = &s;
  work.out = out;
  work.width = width;
  work.height = height;
  work.total = total;
  work.num_trees = num_trees;
  work.stride = stride;
  work.background = background;
  work.use_avx512 = use_avx512;
  work.use_avx2 = use_avx2;
  work.want_foreground = want_foreground;
  work.fg_leaves = out->foreground_leaves.empty() ? nullptr : out->foreground_leaves.data();

  // Phase 2, per chunk of foreground pixels: each tree in turn over the chunk (the top of the
  // tree stays in cache), then sums and argmax while the leaf indices are still in L1.
  // Dynamic scheduling: a thread descheduled by another job leaves its chunks to the others.
#pragma omp parallel num_threads(threads)
  {
    uint32_t* leaves = s.leaves.data() + size_t(omp_get_thread_num()) * size_t(num_trees) * size_t(kChunk);
#pragma omp for schedule(dynamic, 1)
    for (int c = 0; c < num_chunks; ++c) ClassifyChunk(work, c, leaves);
  }
  if (pixel_stride > 1) FillOffGridLabels(depth, pixel_stride, &out->labels);
}

}  // namespace detail

Classifier::Classifier(const core::Forest& forest) : forest_(forest) {
  // Sums are uint16: 255 * trees must fit.
  POSEFOREST_CHECK_MSG(forest.trees.size() <= 65535 / core::kLeafTotal, "too many trees for uint16 sums");
  POSEFOREST_CHECK_MSG(forest.leaf_stride() <= 256, "too many parts");
}

void Classifier::Classify(const core::DepthImage& depth, const ClassifyOptions& options,
                          Classification* out) const {
  detail::ClassifyWithKernel(forest_, depth, options, detail::Kernel::kAuto, out);
}

}  // namespace poseforest::runtime
