#include "engine/vote_learning.h"

#include <omp.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <exception>
#include <mutex>
#include <optional>
#include <thread>

#include "engine/candidates.h"
#include "engine/evaluation.h"
#include "engine/sample_set.h"
#include "runtime/core/rng.h"
#include "runtime/joint_votes.h"

namespace poseforest::engine {

using core::ErrorCode;
using core::Result;
using core::Status;

namespace {

double Now() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

// One training pixel of a tree: its leaf, its back-projected point and whose joints it sees.
struct Pixel {
  uint32_t leaf = 0;
  uint32_t frame = 0;  ///< slot in the tree's frames
  uint8_t person = 0;  ///< index in the frame's people
  Eigen::Vector3f point{0, 0, 0};
};

using Joints = std::array<Eigen::Vector3f, core::kNumJoints>;

// The person a pixel belongs to: the only one, or the ground-truth mask's; -1 when unknown.
int PersonAt(const EvalFrame& f, size_t index) {
  if (f.people.size() == 1) return 0;
  if (f.person_masks.pixels.size() != f.depth.pixels.size()) return -1;
  const int k = int(f.person_masks.pixels[index]) - 1;
  return k >= 0 && k < int(f.people.size()) ? k : -1;
}

// The main mode of `offsets` (mean shift, Gaussian kernel, from up to 8 evenly spaced seeds) and
// how many offsets lie within `bandwidth` of it.
std::pair<Eigen::Vector3f, int> MainMode(const std::vector<Eigen::Vector3f>& offsets, float bandwidth) {
  const float inv = 1.0f / (bandwidth * bandwidth);
  const size_t n = offsets.size();
  const size_t seeds = std::min<size_t>(8, n);
  Eigen::Vector3f best(0, 0, 0);
  float best_density = -1;
  for (size_t s = 0; s < seeds; ++s) {
    Eigen::Vector3f x = offsets[s * n / seeds];
    float density = 0;
    for (int it = 0; it < 12; ++it) {
      Eigen::Vector3f sum(0, 0, 0);
      float sw = 0;
      for (const auto& o : offsets) {
        const float k = std::exp(-(o - x).squaredNorm() * inv);
        sum += k * o;
        sw += k;
      }
      density = sw;
      const Eigen::Vector3f next = sum / sw;
      const float step = (next - x).norm();
      x = next;
      if (step < 5e-4f) break;
    }
    if (density > best_density) best_density = density, best = x;
  }
  int within = 0;
  for (const auto& o : offsets) within += (o - best).squaredNorm() <= bandwidth * bandwidth;
  return {best, within};
}

int16_t Millimetres(float metres) {
  return int16_t(std::clamp(std::lround(double(metres) * 1000.0), -32767L, 32767L));
}

// Pool-adjacent-violators: the non-decreasing fit of `y` weighted by `w`.
std::vector<float> Isotonic(const std::vector<float>& y, const std::vector<double>& w) {
  struct Block {
    double sum, weight;
    size_t count;
  };
  std::vector<Block> blocks;
  for (size_t i = 0; i < y.size(); ++i) {
    blocks.push_back({double(y[i]) * w[i], w[i], 1});
    while (blocks.size() > 1) {
      Block& b = blocks[blocks.size() - 1];
      Block& a = blocks[blocks.size() - 2];
      if (a.sum / std::max(a.weight, 1e-12) <= b.sum / std::max(b.weight, 1e-12)) break;
      a.sum += b.sum, a.weight += b.weight, a.count += b.count;
      blocks.pop_back();
    }
  }
  std::vector<float> out;
  for (const Block& b : blocks) out.insert(out.end(), b.count, float(b.sum / std::max(b.weight, 1e-12)));
  return out;
}

// The forest, job and options fit together: the paper's parts, the job's tree count, options
// in range.
Status CheckInputs(const core::Forest& forest, const TrainParams& job, const VoteLearningOptions& options) {
  if (forest.num_parts != core::kNumParts)
    return Status(ErrorCode::kInvalidArgument, "the forest has " + std::to_string(forest.num_parts) +
                                                   " parts; votes need the paper's 31-part taxonomy");
  if (int(forest.trees.size()) != job.num_trees)
    return Status(ErrorCode::kInvalidArgument, "the forest has " + std::to_string(forest.trees.size()) +
                                                   " trees, the job " + std::to_string(job.num_trees) +
                                                   ": not the forest of this job");
  if (!(options.max_offset_m > 0) || !(options.limb_max_offset_m >= 0) || !(options.hand_max_offset_m >= 0) ||
      !(options.leaf_bandwidth_m > 0) || !(options.vote_bandwidth_m > 0) || options.max_pixels_per_leaf < 1 ||
      !(options.min_weight > 0 && options.min_weight <= 1))
    return Status(ErrorCode::kInvalidArgument, "vote learning options out of range");
  return Status();
}

// The job's frames with joints are its training frames, compared on the first frame of tree 0.
Status CheckTrainingFrames(const TrainParams& job) {
  auto probe = MakeEvalFrameSource(job.source);
  if (!probe.ok()) return probe.status();
  if (!(*probe)->has_joints())
    return Status(ErrorCode::kInvalidArgument,
                  (*probe)->Describe() + ": the job's frames have no joints (votes need rendered frames)");
  // The frames must be the training frames: the first of tree 0 from the training source.
  auto train_src = MakeImageSource(job.source);
  if (!train_src.ok()) return train_src.status();
  auto a = (*probe)->Frame(0);
  auto b = (*train_src)->Frame(0);
  if (!a.ok()) return a.status();
  if (!b.ok()) return b.status();
  if (a->depth.pixels != b->depth.pixels || a->labels.pixels != b->labels.pixels)
    return Status(ErrorCode::kInvalidArgument,
                  (*probe)->Describe() + ": frames with joints differ from the training frames");
  return Status();
}

// A tree's training pixels and the joints of each frame's people, per frame slot.
struct TreePixels {
  std::vector<std::vector<Pixel>> pixels;
  std::vector<std::vector<Joints>> joints;
};

// Frame slot `i` of tree `t`: its people's joints and the pixels SamplePixels drew for it in
// training, each with its leaf in `tree`.
Status WalkTrainingFrame(EvalFrameSource& src, const core::Forest& forest, const core::Tree& tree,
                         const TrainParams& job, int t, int i, TreePixels& out) {
  const uint64_t index = uint64_t(t) * uint64_t(job.images_per_tree) + uint64_t(i);
  auto frame = src.Frame(index);
  if (!frame.ok()) return frame.status();
  const core::CameraIntrinsics cam = src.camera();
  LabelledFrame lf{frame->depth, frame->labels};
  const auto picked = SamplePixels(lf, job.pixels_per_image, job.part_balance,
                                   core::CounterRng(job.seed, uint64_t(t), index, kSamplingStream));
  for (const auto& person : frame->people) {
    Joints j;
    for (int k = 0; k < core::kNumJoints; ++k) j[size_t(k)] = person.position[size_t(k)];
    out.joints[size_t(i)].push_back(j);
  }
  auto& pixels = out.pixels[size_t(i)];
  pixels.reserve(picked.size());
  for (const auto& p : picked) {
    const size_t at = size_t(p.y) * size_t(frame->depth.width) + size_t(p.x);
    const int person = PersonAt(*frame, at);
    const uint16_t d = frame->depth.pixels[at];
    if (person < 0 || d == 0) continue;
    Pixel px;
    px.leaf = runtime::LeafOf(tree, forest.constants, frame->depth, p.x, p.y);
    px.frame = uint32_t(i);
    px.person = uint8_t(person);
    px.point = cam.Unproject(p.x, p.y, d * 1e-3).cast<float>();
    pixels.push_back(px);
  }
  return Status();
}

// The training pixels of tree `t` (threads render; results land in slots).
Result<TreePixels> RenderTreePixels(const core::Forest& forest, const TrainParams& job,
                                    const VoteLearningOptions& options, int t, int threads, double t_tree) {
  const core::Tree& tree = forest.trees[size_t(t)];
  const int ipt = job.images_per_tree;
  TreePixels out;
  out.pixels.resize(static_cast<size_t>(ipt));
  out.joints.resize(static_cast<size_t>(ipt));
  std::vector<Status> errors(static_cast<size_t>(threads));
  std::atomic<int> done{0};
  std::mutex progress_mu;
  std::vector<std::thread> pool;
  for (int tid = 0; tid < threads; ++tid)
    pool.emplace_back([&, tid] {
      try {
        auto src = MakeEvalFrameSource(job.source);
        if (!src.ok()) {
          errors[size_t(tid)] = src.status();
          return;
        }
        for (int i = tid; i < ipt; i += threads) {
          const Status walked = WalkTrainingFrame(**src, forest, tree, job, t, i, out);
          if (!walked.ok()) {
            errors[size_t(tid)] = walked;
            return;
          }
          const int n = ++done;
          if (options.progress && (n % 100 == 0 || n == ipt)) {
            char line[160];
            std::snprintf(line, sizeof line, "tree %d: %d / %d training frames rendered and walked (%.0f s)",
                          t, n, ipt, Now() - t_tree);
            std::lock_guard<std::mutex> lock(progress_mu);
            options.progress(line);
          }
        }
      } catch (const std::exception& e) {
        errors[size_t(tid)] = Status(ErrorCode::kInternal, std::string("rendering frames: ") + e.what());
      }
    });
  for (auto& th : pool) th.join();
  for (const Status& e : errors)
    if (!e.ok()) return e;
  return out;
}

// The vote of joint `j` at a leaf: the main mode of the offsets from the leaf's pixels (thinned
// evenly to `keep`) to the joint, if it holds enough of them.
std::optional<core::JointVote> LeafJointVote(const std::vector<const Pixel*>& by_leaf, uint32_t b, uint32_t n,
                                             uint32_t keep, int j, const TreePixels& tp,
                                             const VoteLearningOptions& options,
                                             std::vector<Eigen::Vector3f>& offsets) {
  const float reach = VoteReach(j, options);
  const float max2 = reach * reach;
  offsets.clear();
  for (uint32_t k = 0; k < keep; ++k) {
    const Pixel& p = *by_leaf[b + uint32_t(uint64_t(k) * n / keep)];
    const Eigen::Vector3f o = tp.joints[p.frame][p.person][size_t(j)] - p.point;
    if (o.squaredNorm() < max2) offsets.push_back(o);
  }
  if (offsets.empty() || float(offsets.size()) < options.min_weight * float(keep)) return std::nullopt;
  const auto [mode, within] = MainMode(offsets, options.leaf_bandwidth_m);
  const float weight = float(within) / float(keep);
  if (weight < options.min_weight) return std::nullopt;
  core::JointVote v;
  v.dx_mm = Millimetres(mode.x());
  v.dy_mm = Millimetres(mode.y());
  v.dz_mm = Millimetres(mode.z());
  v.joint = uint8_t(j);
  v.weight = uint8_t(std::clamp<long>(std::lround(weight * 255.0f), 1L, 255L));
  return v;
}

// The votes of one tree from its training pixels.
core::TreeVotes TreeVotesOf(const core::Tree& tree, const TreePixels& tp, const VoteLearningOptions& options,
                            int threads, VoteLearningReport& rep, uint64_t& total) {
  // --- Pixels grouped by leaf, in (frame, pixel) order. ---
  std::vector<uint32_t> first(size_t(tree.num_leaves) + 1, 0);
  total = 0;
  for (const auto& f : tp.pixels)
    for (const Pixel& p : f) ++first[size_t(p.leaf) + 1], ++total;
  for (size_t l = 1; l < first.size(); ++l) first[l] += first[l - 1];
  std::vector<const Pixel*> by_leaf(total);
  {
    std::vector<uint32_t> at(first.begin(), first.end() - 1);
    for (const auto& f : tp.pixels)
      for (const Pixel& p : f) by_leaf[at[p.leaf]++] = &p;
  }
  rep.pixels += total;
  rep.leaves += tree.num_leaves;
  for (uint32_t l = 0; l < tree.num_leaves; ++l) rep.leaves_unreached += first[l] == first[l + 1];
  // --- Per leaf and joint, the main mode of the offsets. ---
  std::vector<std::vector<core::JointVote>> leaf_votes(tree.num_leaves);
#pragma omp parallel for schedule(dynamic, 256) num_threads(threads)
  for (int64_t l = 0; l < int64_t(tree.num_leaves); ++l) {
    const uint32_t b = first[size_t(l)], e = first[size_t(l) + 1];
    const uint32_t n = e - b;
    if (n == 0) continue;
    const uint32_t keep = std::min<uint32_t>(n, uint32_t(options.max_pixels_per_leaf));
    std::vector<Eigen::Vector3f> offsets;
    offsets.reserve(keep);
    for (int j = 0; j < core::kNumJoints; ++j)
      if (const auto v = LeafJointVote(by_leaf, b, n, keep, j, tp, options, offsets))
        leaf_votes[size_t(l)].push_back(*v);
  }
  core::TreeVotes tv;
  tv.first.resize(size_t(tree.num_leaves) + 1, 0);
  for (uint32_t l = 0; l < tree.num_leaves; ++l) {
    tv.first[l + 1] = tv.first[l] + uint32_t(leaf_votes[l].size());
    rep.leaves_with_votes += !leaf_votes[l].empty();
  }
  tv.votes.reserve(tv.first.back());
  for (auto& v : leaf_votes) tv.votes.insert(tv.votes.end(), v.begin(), v.end());
  rep.votes += tv.votes.size();
  return tv;
}

// A one-person validation frame, its person's mask and joints, kept for the bandwidth search.
struct Valid {
  core::DepthImage depth;
  core::LabelImage mask;
  Joints truth;
};

// The one-person frames among the first options.validation_frames of `src`.
Result<std::vector<Valid>> RenderValidation(EvalFrameSource& src, const VoteLearningOptions& options) {
  std::vector<Valid> valid;
  for (int i = 0; i < options.validation_frames; ++i) {
    auto frame = src.Frame(uint64_t(i));
    if (!frame.ok()) return frame.status();
    if (frame->people.size() != 1) continue;
    const bool has_mask = frame->person_masks.pixels.size() == frame->depth.pixels.size();
    Valid v{std::move(frame->depth), core::LabelImage(frame->depth.width, frame->depth.height, 0), {}};
    for (size_t k = 0; k < v.mask.pixels.size(); ++k)
      v.mask.pixels[k] = has_mask ? (frame->person_masks.pixels[k] == 1) : (v.depth.pixels[k] ? 1 : 0);
    for (int j = 0; j < core::kNumJoints; ++j) v.truth[size_t(j)] = frame->people[0].position[size_t(j)];
    valid.push_back(std::move(v));
    if (options.progress && ((i + 1) % 20 == 0 || i + 1 == options.validation_frames)) {
      char line[120];
      std::snprintf(line, sizeof line, "validation: %d / %d frames rendered", i + 1,
                    options.validation_frames);
      options.progress(line);
    }
  }
  return valid;
}

// Per joint, the run-time bandwidth whose most weighted candidate is right most often on
// these frames (the grid's first value wins ties); sets table.bandwidth_m and rep.bandwidth_m.
// `with` is the forest, its votes replaced as each bandwidth is tried.
void ChooseBandwidths(core::Forest& with, const std::vector<Valid>& valid, const core::CameraIntrinsics& cam,
                      const VoteLearningOptions& options, core::OffsetVotes& table, VoteLearningReport& rep) {
  const std::vector<float> grid =
      options.bandwidth_grid.empty() ? std::vector<float>{options.vote_bandwidth_m} : options.bandwidth_grid;
  if (grid.size() > 1) {
    std::array<int, core::kNumJoints> best_hits{};
    best_hits.fill(-1);
    for (const float b : grid) {
      table.bandwidth_m.fill(b);
      with.offset_votes = table;
      std::array<int, core::kNumJoints> hits_b{};
      for (const Valid& v : valid) {
        const auto cands = runtime::CastVotes(with, v.depth, v.mask, 1, cam);
        for (int j = 0; j < core::kNumJoints; ++j) {
          const auto& cj = cands[0][size_t(j)];
          if (cj.empty()) continue;
          size_t top = 0;
          for (size_t k = 1; k < cj.size(); ++k)
            if (cj[k].share > cj[top].share) top = k;
          hits_b[size_t(j)] += (cj[top].position - v.truth[size_t(j)]).norm() <= 0.1f;
        }
      }
      for (int j = 0; j < core::kNumJoints; ++j)
        if (hits_b[size_t(j)] > best_hits[size_t(j)])
          best_hits[size_t(j)] = hits_b[size_t(j)], rep.bandwidth_m[size_t(j)] = b;
      if (options.progress) {
        char line[120];
        std::snprintf(line, sizeof line, "bandwidth %.3f m tried on %zu frames", double(b), valid.size());
        options.progress(line);
      }
    }
    table.bandwidth_m = rep.bandwidth_m;
  } else {
    table.bandwidth_m.fill(grid[0]);
    rep.bandwidth_m = table.bandwidth_m;
  }
}

// Share bins of the calibration, and per (joint, bin) the candidates and those within 0.1 m.
const std::vector<float> kShareEdges = {0.0f,  0.02f, 0.04f, 0.06f, 0.08f, 0.1f, 0.13f,
                                        0.16f, 0.2f,  0.25f, 0.3f,  0.4f,  0.5f};

struct BinCounts {
  std::vector<double> hits, count;
};

// The candidates of `with` (the forest with the table's votes) on the validation frames,
// counted per (joint, share bin).
BinCounts ScoreCandidates(const core::Forest& with, const std::vector<Valid>& valid,
                          const core::CameraIntrinsics& cam, VoteLearningReport& rep) {
  const std::vector<float>& edges = kShareEdges;
  const size_t bins = edges.size();
  BinCounts c{std::vector<double>(bins * core::kNumJoints, 0),
              std::vector<double>(bins * core::kNumJoints, 0)};
  for (const Valid& v : valid) {
    const auto cands = runtime::CastVotes(with, v.depth, v.mask, 1, cam);
    for (int j = 0; j < core::kNumJoints; ++j) {
      const auto& cj = cands[0][size_t(j)];
      const Eigen::Vector3f truth = v.truth[size_t(j)];
      ++rep.scored[size_t(j)];
      if (!cj.empty()) {
        // Candidates come most confident first; without a table, most weight first.
        size_t top = 0;
        for (size_t k = 1; k < cj.size(); ++k)
          if (cj[k].share > cj[top].share) top = k;
        rep.top_within[size_t(j)] += (cj[top].position - truth).norm() <= 0.1f;
      }
      for (const auto& cand : cj) {
        size_t bin = 0;
        while (bin + 1 < edges.size() && cand.share >= edges[bin + 1]) ++bin;
        c.count[size_t(j) * bins + bin] += 1;
        c.hits[size_t(j) * bins + bin] += (cand.position - truth).norm() <= 0.1f;
        ++rep.candidates;
      }
    }
  }
  return c;
}

// Per joint, each bin's precision, pulled towards the joint's overall rate by two pseudo-
// candidates, then made non-decreasing (more of the joint's weight is never less likely
// right).
void FitPrecision(const BinCounts& c, core::OffsetVotes& table) {
  const size_t bins = kShareEdges.size();
  table.share_edges = kShareEdges;
  for (int j = 0; j < core::kNumJoints; ++j) {
    double all_hits = 0, all = 0;
    for (size_t b = 0; b < bins; ++b)
      all_hits += c.hits[size_t(j) * bins + b], all += c.count[size_t(j) * bins + b];
    const double overall = all > 0 ? all_hits / all : 0.0;
    std::vector<float> precision(bins);
    std::vector<double> weight(bins);
    for (size_t b = 0; b < bins; ++b) {
      precision[b] =
          float((c.hits[size_t(j) * bins + b] + 2 * overall) / (c.count[size_t(j) * bins + b] + 2));
      weight[b] = c.count[size_t(j) * bins + b] + 2;
    }
    const auto fit = Isotonic(precision, weight);
    table.precision.insert(table.precision.end(), fit.begin(), fit.end());
  }
}

// Calibration on validation frames: the run-time bandwidths, then precision per bin of share.
Status Calibrate(const core::Forest& forest, const VoteLearningOptions& options, core::OffsetVotes& table,
                 VoteLearningReport& rep) {
  auto src = MakeEvalFrameSource(options.validation);
  if (!src.ok()) return src.status();
  if (!(*src)->has_joints())
    return Status(ErrorCode::kInvalidArgument, (*src)->Describe() + ": validation frames have no joints");
  const core::CameraIntrinsics cam = (*src)->camera();
  auto valid = RenderValidation(**src, options);
  if (!valid.ok()) return valid.status();
  rep.validation_frames = int(valid->size());
  core::Forest with = forest;
  ChooseBandwidths(with, *valid, cam, options, table, rep);
  with.offset_votes = table;
  const BinCounts counts = ScoreCandidates(with, *valid, cam, rep);
  FitPrecision(counts, table);
  return Status();
}

}  // namespace

float VoteReach(int j, const VoteLearningOptions& options) {
  if (j < int(core::Joint::kLElbow)) return options.max_offset_m;
  const float limb = options.limb_max_offset_m > 0 ? options.limb_max_offset_m : options.max_offset_m;
  const bool hand = j >= int(core::Joint::kLWrist) && j <= int(core::Joint::kRHand);
  return hand && options.hand_max_offset_m > 0 ? options.hand_max_offset_m : limb;
}

Result<core::OffsetVotes> LearnOffsetVotes(const core::Forest& forest, const TrainParams& job,
                                           const VoteLearningOptions& options, VoteLearningReport* report) {
  const double t0 = Now();
  VoteLearningReport rep;
  if (Status s = CheckInputs(forest, job, options); !s.ok()) return s;
  const int threads =
      options.threads > 0 ? options.threads : std::max(1u, std::thread::hardware_concurrency());
  if (Status s = CheckTrainingFrames(job); !s.ok()) return s;
  core::OffsetVotes table;
  table.max_offset_m = 0;
  for (int j = 0; j < core::kNumJoints; ++j)
    table.max_offset_m = std::max(table.max_offset_m, VoteReach(j, options));
  table.bandwidth_m.fill(options.vote_bandwidth_m);
  for (int t = 0; t < job.num_trees; ++t) {
    const core::Tree& tree = forest.trees[size_t(t)];
    const double t_tree = Now();
    auto tp = RenderTreePixels(forest, job, options, t, threads, t_tree);
    if (!tp.ok()) return tp.status();
    uint64_t total = 0;
    const uint64_t unreached_before = rep.leaves_unreached;
    table.trees.push_back(TreeVotesOf(tree, *tp, options, threads, rep, total));
    const uint64_t unreached = rep.leaves_unreached - unreached_before;
    // Every leaf of a tree holds some of the training pixels that made it, and learn-votes walks
    // exactly those pixels: the job's own forest leaves no leaf unreached. A forest of another
    // job (another seed, source or images per tree) leaves many; 1 % allows for nothing else.
    if (unreached * 100 > tree.num_leaves)
      return Status(ErrorCode::kInvalidArgument,
                    "tree " + std::to_string(t) + ": " + std::to_string(unreached) + " of " +
                        std::to_string(tree.num_leaves) +
                        " leaves were reached by none of the job's training pixels (the job that trained "
                        "the forest leaves none): not the forest of this job (another seed, source or "
                        "images_per_tree?)");
    if (options.progress) {
      char line[240];
      std::snprintf(
          line, sizeof line,
          "tree %d: %llu pixels, %u leaves (%.1f pixels each, %llu reached by none), %zu votes (%.0f s)", t,
          (unsigned long long)total, tree.num_leaves, double(total) / std::max(1u, tree.num_leaves),
          (unsigned long long)unreached, table.trees.back().votes.size(), Now() - t_tree);
      options.progress(line);
    }
  }
  if (options.validation_frames > 0)
    if (Status s = Calibrate(forest, options, table, rep); !s.ok()) return s;
  rep.seconds = Now() - t0;
  if (report) *report = rep;
  return table;
}

}  // namespace poseforest::engine
