// Training throughput: feature evaluations per second per core in the histogram builder
// (one evaluation = one sample x one candidate: the eq. 1 response, its threshold bin and the
// count), at the root (one node holding every sample) and at a deep level (thousands of small
// nodes, reached by random splits). Frames are procedural 640x480 figures at 1.5-4 m, pixels
// sampled as in training.
//
// Per core = per CPU second of the process (the build machine is shared, so wall time
// understates it; the wall figure is printed too). Headline (last line): root + deep level.
//
// Side by side (--compare sklearn, the default when /usr/bin/python3 imports sklearn): the same
// pixels' responses to the root's candidates, written as an N x K float32 matrix, fitted by
// scikit-learn's ExtraTreesClassifier (one tree, every candidate at every node, entropy, same
// depth and min_samples_split, n_jobs=1; bench/sklearn_side_by_side.py times fit() alone),
// against our engine (engine::LocalTrainer, 1 thread) training one tree of the same depth
// on the same pixels, feature computation included.
//
// usage: train [--source procedural|rendered] [--images N] [--pixels N] [--candidates N] [--thresholds N]
// [--depth D] [--threads N] [--compare auto|sklearn|none] [--compare-depth D] [--sklearn-model extra|forest]
// [--sklearn-script PATH] (--help)
#include <CLI/CLI.hpp>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <string>

#include "bench/bench_cli.h"
#include "engine/candidates.h"
#include "engine/histogram_builder.h"
#include "engine/image_source.h"
#include "engine/local_trainer.h"
#include "engine/sample_set.h"
#include "runtime/core/malloc_tuning.h"
#include "runtime/core/rng.h"

using namespace poseforest;

namespace {

double Now() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}
/// CPU seconds of the whole process (all threads): the machine may be shared, so per-core
/// throughput is evaluations per CPU second, not per wall second.
double Cpu() {
  timespec ts;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}

struct Figures {
  double build_evals_per_s = 0, range_s = 0, build_s = 0, build_cpu_s = 0, range_cpu_s = 0;
  double cuts_cpu_s = 0;  ///< of range_cpu_s: DrawCuts
  uint64_t evals = 0;
  size_t nodes = 0;
};

/// Ranges + cuts + histograms for every node of the set's frontier, in batches of `batch`.
Figures RunLevel(const engine::SampleSet& set, const engine::TrainParams& p, int threads, size_t batch) {
  engine::HistogramBuilder builder(p.constants, threads);
  Figures fig;
  const auto& ranges = set.ranges();
  fig.nodes = ranges.size();
  for (size_t b0 = 0; b0 < ranges.size(); b0 += batch) {
    std::vector<engine::NodePlan> plans;
    for (size_t i = b0; i < std::min(ranges.size(), b0 + batch); ++i) {
      engine::NodePlan plan;
      plan.node = ranges[i].node;
      plan.position = plan.node;
      plan.num_samples = ranges[i].end - ranges[i].begin;
      std::vector<uint64_t> parts(core::kNumParts);
      set.CountParts(ranges[i], core::kNumParts, parts.data());
      plan.SetParts(parts);
      plan.sample_bins = engine::UseSampleBins(plan.num_samples, p.thresholds_per_feature, plan.num_slots);
      plan.features = engine::DrawFeatures(p, 0, plan.node);
      plan.cut_stride = engine::CutStride(p.thresholds_per_feature);
      plans.push_back(std::move(plan));
    }
    const double t0 = Now(), c0 = Cpu();
    std::vector<std::vector<engine::ResponseRange>> rr;
    builder.ComputeRanges(set, p, 0, plans, &rr);
    const double cc = Cpu();
    for (size_t i = 0; i < plans.size(); ++i) plans[i].cuts = engine::DrawCuts(p, 0, plans[i].node, rr[i]);
    const double t1 = Now(), c1 = Cpu();
    fig.cuts_cpu_s += c1 - cc;
    fig.range_cpu_s += c1 - c0;
    std::vector<engine::NodeHistogram> hists;
    builder.Build(set, plans, p.thresholds_per_feature, &hists);
    const double t2 = Now();
    fig.build_cpu_s += Cpu() - c1;
    fig.range_s += t1 - t0;
    fig.build_s += t2 - t1;
  }
  fig.evals = builder.evaluations();
  fig.build_evals_per_s = double(fig.evals) / fig.build_s;
  return fig;
}

/// Writes a 2-D (cols > 0) or 1-D array as a NumPy .npy file (format 1.0, C order).
bool WriteNpy(const std::filesystem::path& path, const void* data, size_t bytes, const char* descr, size_t rows,
              size_t cols) {
  std::string dict = std::string("{'descr': '") + descr + "', 'fortran_order': False, 'shape': (" +
                     std::to_string(rows) + (cols ? ", " + std::to_string(cols) + ")" : std::string(",)")) + ", }";
  const size_t unpadded = 10 + dict.size() + 1;
  dict.append((64 - unpadded % 64) % 64, ' ');
  dict += '\n';
  std::ofstream f(path, std::ios::binary);
  const auto len = uint16_t(dict.size());
  f.write("\x93NUMPY\x01\x00", 8);
  f.write(reinterpret_cast<const char*>(&len), 2);
  f.write(dict.data(), std::streamsize(dict.size()));
  f.write(static_cast<const char*>(data), std::streamsize(bytes));
  return bool(f);
}

struct CompareOptions {
  std::string mode = "auto";  ///< auto (sklearn when available) | sklearn | none
  int depth = 20;
  std::string model = "extra";
  std::string script = POSEFOREST_SKLEARN_SCRIPT;
};

constexpr const char* kPython = "/usr/bin/python3";

/// Why the sklearn side by side cannot run, or "" when it can.
std::string SklearnMissing(const CompareOptions& o) {
  if (!std::filesystem::exists(kPython)) return std::string(kPython) + " does not exist";
  if (!std::filesystem::exists(o.script)) return "script " + o.script + " not found (--sklearn-script)";
  const std::string cmd = std::string(kPython) + " -c 'import sklearn, numpy' > /dev/null 2>&1";
  if (std::system(cmd.c_str()) != 0)
    return std::string(kPython) + " cannot import sklearn/numpy (Debian: apt-get install python3-sklearn)";
  return "";
}

/// The side by side: sklearn's fit() on the precomputed responses vs our engine training the
/// same tree shape on the same pixels from the frames (features computed as it goes).
void SideBySide(const engine::SampleSet& set, const engine::TrainParams& p, int images, int pixels,
                const CompareOptions& o) {
  const auto features = engine::DrawFeatures(p, 0, 0);
  const size_t n = set.num_samples(), k = features.size();
  std::printf("side by side: %zu samples x %zu candidates, depth %d, min_samples_split %lld, 1 thread each\n", n,
              k, o.depth, static_cast<long long>(p.min_samples_split));
  std::fflush(stdout);
  // The matrix: responses of every sample to the root's candidates (what sklearn gets for free).
  const double m0 = Cpu();
  std::vector<float> x(n * k);
  std::vector<uint8_t> y(n);
  for (size_t i = 0; i < n; ++i) {
    y[i] = set.part()[i];
    for (size_t c = 0; c < k; ++c) x[i * k + c] = float(set.Response(i, features[c], p.constants.background_mm));
  }
  char tmpl[] = "/tmp/poseforest_train_cmp_XXXXXX";
  if (!mkdtemp(tmpl)) {
    std::printf("side by side skipped: cannot create a temporary directory under /tmp\n");
    return;
  }
  const std::filesystem::path dir(tmpl);
  const bool written = WriteNpy(dir / "x.npy", x.data(), x.size() * sizeof(float), "<f4", n, k) &&
                       WriteNpy(dir / "y.npy", y.data(), y.size(), "|u1", n, 0);
  x = {};
  std::printf("  feature matrix for sklearn: %.0f MB, computed in %.2f s CPU (not counted for either side)\n",
              double(n * k * sizeof(float)) / 1e6, Cpu() - m0);
  std::fflush(stdout);
  double sk_cpu = -1, sk_wall = -1, sk_acc = -1;
  int sk_nodes = 0, sk_depth = 0;
  std::string sk_line;
  if (written) {
    const std::string cmd = std::string(kPython) + " " + o.script + " --x " + (dir / "x.npy").string() + " --y " +
                            (dir / "y.npy").string() + " --depth " + std::to_string(o.depth) +
                            " --min-samples-split " + std::to_string(p.min_samples_split) + " --model " + o.model +
                            " 2>&1";
    if (FILE* pipe = popen(cmd.c_str(), "r")) {
      char buf[1024];
      while (std::fgets(buf, sizeof buf, pipe)) {
        const std::string line(buf);
        if (line.rfind("sklearn:", 0) == 0) {
          sk_line = line;
          const char* q = std::strstr(buf, "fit_cpu_s=");
          if (q)
            std::sscanf(q, "fit_cpu_s=%lf fit_wall_s=%lf nodes=%d depth=%d train_accuracy=%lf", &sk_cpu, &sk_wall,
                        &sk_nodes, &sk_depth, &sk_acc);
        } else {
          std::printf("  [sklearn script] %s", buf);
        }
      }
      const int rc = pclose(pipe);
      if (rc != 0) std::printf("  sklearn script exited with status %d\n", rc);
    }
  } else {
    std::printf("  could not write the matrix under %s\n", dir.c_str());
  }
  std::error_code ec;
  std::filesystem::remove_all(dir, ec);
  if (sk_cpu < 0) {
    std::printf("side by side: no sklearn timing (see the lines above)\n");
    return;
  }
  // Ours: the engine trains tree 0 of the same job (same frames, same sampled pixels).
  engine::TrainParams q = p;
  q.num_trees = 1;
  q.max_depth = o.depth;
  q.images_per_tree = images;
  q.pixels_per_image = pixels;
  q.threads = 1;
  engine::LocalTrainer trainer(q, {});
  const double c0 = Cpu(), w0 = Now();
  auto tree = trainer.TrainTree(0);
  const double ours_cpu = Cpu() - c0, ours_wall = Now() - w0;
  if (!tree.ok()) {
    std::printf("side by side: our engine failed: %s\n", tree.status().ToString().c_str());
    return;
  }
  const auto& st = trainer.stats();
  if (st.samples != n)
    std::printf("  WARNING: the engine sampled %llu pixels, the matrix has %zu\n",
                static_cast<unsigned long long>(st.samples), n);
  const bool forest = o.model == "forest";
  std::printf("  sklearn %s, 1 tree, %zu features at every node, %s: fit %.2f s CPU "
              "(%.2f s wall), %d nodes, depth %d, training accuracy %.3f\n",
              forest ? "RandomForestClassifier" : "ExtraTreesClassifier", k,
              forest ? "every threshold (best split)" : "1 random threshold each", sk_cpu, sk_wall, sk_nodes,
              sk_depth, sk_acc);
  std::printf("  ours (LocalTrainer, 1 thread), %zu fresh candidates x %d thresholds at every node, features "
              "computed from the frames: %.2f s CPU (%.2f s wall, of which %.2f s loading frames + sampling, "
              "%.2f s histograms incl. fused passes, %.2f s threshold ranges), %zu nodes, depth %u, %.3g evaluations\n",
              k, p.thresholds_per_feature, ours_cpu, ours_wall, st.load_seconds, st.histogram_seconds,
              st.range_seconds, tree->nodes.size(), tree->depth, double(st.evaluations));
  std::printf("side by side: sklearn fit / ours = %.2f (CPU seconds; ours includes computing the features and "
              "loading the frames, theirs does not)\n",
              sk_cpu / ours_cpu);
}

}  // namespace

int main(int argc, char** argv) {
  poseforest::core::KeepFreedMemory();  // runtime/core/malloc_tuning.h
  // Defaults: the paper's per-node search (2000 features x 50 thresholds, 2000 pixels/frame).
  int images = 20, pixels = 2000, candidates = 2000, thresholds = 50, depth = 10, threads = 1;
  CompareOptions compare;
  std::string source_kind = "procedural";
  CLI::App app(
      "Histogram-builder throughput (evaluations/s/core, last line), then a side by side with\n"
      "scikit-learn (default auto: when /usr/bin/python3 imports sklearn; the reason is printed\n"
      "when it is skipped)",
      "bench/train");
  app.add_option("--source", source_kind, "the frames: procedural figures, or rendered people")
      ->type_name("procedural|rendered")
      ->capture_default_str()
      ->check(CLI::IsMember({"procedural", "rendered"}));
  app.add_option("--images", images, "frames")
      ->type_name("N")
      ->capture_default_str()
      ->check(CLI::Range(1, 1000000));
  app.add_option("--pixels", pixels, "pixels sampled per frame")
      ->type_name("N")
      ->capture_default_str()
      ->check(CLI::Range(1, 307200));
  app.add_option("--candidates", candidates, "candidate features per node")
      ->type_name("N")
      ->capture_default_str()
      ->check(CLI::Range(1, 100000));
  app.add_option("--thresholds", thresholds, "thresholds per feature")
      ->type_name("N")
      ->capture_default_str()
      ->check(CLI::Range(1, 10000));
  app.add_option("--depth", depth, "depth of the deep level timed")
      ->type_name("D")
      ->capture_default_str()
      ->check(CLI::Range(1, 30));
  app.add_option("--threads", threads, "threads")
      ->type_name("N")
      ->capture_default_str()
      ->check(CLI::Range(1, 1024));
  app.add_option("--compare", compare.mode, "the scikit-learn side by side")
      ->type_name("auto|sklearn|none")
      ->capture_default_str()
      ->check(CLI::IsMember({"auto", "sklearn", "none"}));
  app.add_option("--compare-depth", compare.depth, "depth of the side by side's trees")
      ->type_name("D")
      ->capture_default_str()
      ->check(CLI::Range(1, 30));
  app.add_option("--sklearn-model", compare.model, "ExtraTreesClassifier or RandomForestClassifier")
      ->type_name("extra|forest")
      ->capture_default_str()
      ->check(CLI::IsMember({"extra", "forest"}));
  app.add_option("--sklearn-script", compare.script, "the side by side's Python script")
      ->type_name("PATH")
      ->capture_default_str()
      ->check(bench::kNonEmptyPath);
  if (const auto exit_status = bench::ParseBenchCommandLine(app, argc, argv)) return *exit_status;
  const bool rendered = source_kind == "rendered";
  engine::TrainParams p;
  p.seed = 1;
  p.candidate_features = candidates;
  p.thresholds_per_feature = thresholds;
  p.source.kind = rendered ? engine::SourceKind::kRendered : engine::SourceKind::kProcedural;
  p.source.width = 640;
  p.source.height = 480;
  auto source = engine::MakeImageSource(p.source);
  if (!source.ok()) {
    std::fprintf(stderr, "train bench: %s\n", source.status().ToString().c_str());
    return 1;
  }
  // As LocalTrainer loads a shard: frames compacted as they come, then added with exact room.
  std::vector<engine::CompactFrame> compact(static_cast<size_t>(images));
  std::vector<std::vector<engine::PixelSample>> picked(static_cast<size_t>(images));
  size_t span_pixels = 0, rows = 0, samples = 0;
  for (int i = 0; i < images; ++i) {
    auto frame = (*source)->Frame(uint64_t(i));
    if (!frame.ok()) {
      std::fprintf(stderr, "train bench: %s\n", frame.status().ToString().c_str());
      return 1;
    }
    picked[size_t(i)] = engine::SamplePixels(*frame, pixels, 1.0,
                                             core::CounterRng(1, 0, uint64_t(i), engine::kSamplingStream));
    compact[size_t(i)] = engine::CompactFrame::Of(frame->depth, p.constants.background_mm);
    span_pixels += compact[size_t(i)].pixels.size();
    rows += compact[size_t(i)].rows.size();
    samples += picked[size_t(i)].size();
  }
  engine::SampleSet set;
  set.Reserve(size_t(images), span_pixels, samples, rows);
  for (int i = 0; i < images; ++i)
    set.AddFrame(uint64_t(i), compact[size_t(i)], picked[size_t(i)], p.constants);
  compact = {};
  picked = {};
  set.StartTree(0);
  std::printf("train bench: %d %s frames 640x480, %zu samples, %d candidates x %d thresholds, %d thread(s)\n",
              images, rendered ? "rendered" : "procedural", set.num_samples(), candidates, thresholds,
              threads);
  const uint64_t set_bytes = set.MemoryBytes();
  std::printf(
      "memory: frames+samples %.1f MiB for %d images: %llu bytes per image (frames %.0f span pixels, %zu "
      "rows; "
      "%.0f samples)\n",
      double(set_bytes) / 1048576.0, images, static_cast<unsigned long long>(set_bytes / uint64_t(images)),
      double(span_pixels) / images, rows / size_t(images), double(samples) / images);

  // The side by side runs on the pixels before the deep level's splits (a copy).
  std::string compare_skipped;
  if (compare.mode == "none") {
    compare_skipped = "--compare none";
  } else {
    compare_skipped = SklearnMissing(compare);
    if (!compare_skipped.empty() && compare.mode == "sklearn") {
      std::fprintf(stderr, "train bench: --compare sklearn: %s\n", compare_skipped.c_str());
      return 1;
    }
  }
  const engine::SampleSet compare_set = compare_skipped.empty() ? set : engine::SampleSet();

  const Figures root = RunLevel(set, p, threads, 1);
  std::printf(
      "root:     1 node,  %.3g evaluations in %.2f s wall, %.2f s CPU (+ ranges %.2f s wall, %.2f s CPU of which "
      "DrawCuts %.2f s): %.3g evaluations/s wall, %.3g per CPU second\n",
      double(root.evals), root.build_s, root.build_cpu_s, root.range_s, root.range_cpu_s, root.cuts_cpu_s,
      root.build_evals_per_s, double(root.evals) / root.build_cpu_s);

  // Deep level: split every node by a random candidate at the response of its first sample,
  // `depth` times (the shape of a real level: many nodes, few samples each).
  for (int level = 0; level < depth; ++level) {
    std::vector<engine::SampleSet::Split> splits;
    uint32_t next = 0;
    for (const auto& r : set.ranges()) {
      const core::CounterRng rng(7, uint64_t(level), r.node, 0);
      const auto f = engine::DrawFeatures(p, 0, r.node)[rng.UniformInt(0, uint32_t(candidates))];
      const size_t s = r.begin + (r.end - r.begin) / 2;
      const int32_t cut = set.Response(s, f, p.constants.background_mm);
      splits.push_back({r.node, f, cut, next});
      next += 2;
    }
    set.ApplySplits(splits, p.constants, threads);
  }
  const Figures deep = RunLevel(set, p, threads, 256);
  // The same level through the fused single-shard pass (what LocalTrainer runs for nodes whose
  // samples all sit on one shard): ranges + cuts + histograms with one evaluation per sample
  // and candidate.
  double fused_cpu = 0;
  uint64_t fused_evals = 0;
  {
    engine::HistogramBuilder builder(p.constants, threads);
    const auto& ranges = set.ranges();
    for (size_t b0 = 0; b0 < ranges.size(); b0 += 256) {
      std::vector<engine::NodePlan> plans;
      for (size_t i = b0; i < std::min(ranges.size(), b0 + 256); ++i) {
        engine::NodePlan plan;
        plan.node = ranges[i].node;
        plan.position = plan.node;
        plan.num_samples = ranges[i].end - ranges[i].begin;
        std::vector<uint64_t> parts(core::kNumParts);
        set.CountParts(ranges[i], core::kNumParts, parts.data());
        plan.SetParts(parts);
        plan.sample_bins = engine::UseSampleBins(plan.num_samples, p.thresholds_per_feature, plan.num_slots);
        plan.features = engine::DrawFeatures(p, 0, plan.node);
        if (engine::HistogramBuilder::CanFuse(set, p, plan)) plans.push_back(std::move(plan));
      }
      const double c0 = Cpu();
      std::vector<engine::NodeHistogram> hists;
      builder.BuildFused(set, p, 0, plans, &hists);
      fused_cpu += Cpu() - c0;
    }
    fused_evals = builder.evaluations();
  }
  std::printf(
      "level %d: %zu nodes (%.0f samples/node), %.3g evaluations in %.2f s wall, %.2f s CPU (+ ranges %.2f s "
      "wall, %.2f s CPU of which DrawCuts %.2f s): %.3g evaluations/s wall, %.3g per CPU second\n",
      depth, deep.nodes, double(set.num_samples()) / double(deep.nodes), double(deep.evals), deep.build_s,
      deep.build_cpu_s, deep.range_s, deep.range_cpu_s, deep.cuts_cpu_s, deep.build_evals_per_s,
      double(deep.evals) / deep.build_cpu_s);
  std::printf(
      "level %d fused (ranges + cuts + histograms in one pass, %.3g evaluations): %.3g evaluations per CPU "
      "second\n",
      depth, double(fused_evals), double(fused_evals) / fused_cpu);
  if (compare_skipped.empty())
    SideBySide(compare_set, p, images, pixels, compare);
  else
    std::printf("side by side with scikit-learn skipped: %s\n", compare_skipped.c_str());
  std::printf("wall-clock per core (shared machine, pessimistic): %.4g evaluations/s/core\n",
              double(root.evals + deep.evals) / (root.build_s + deep.build_s) / threads);
  std::printf("with the threshold-range pass counted as overhead: %.4g evaluations/s/core (CPU)\n",
              double(root.evals + deep.evals) /
                  (root.build_cpu_s + deep.build_cpu_s + root.range_cpu_s + deep.range_cpu_s));
  const double all = double(root.evals + deep.evals) / (root.build_cpu_s + deep.build_cpu_s);
  std::printf(
      "(root + level %d together, per CPU second; the threshold-range pass is reported separately above)\n",
      depth);
  std::printf("evaluations/s/core: %.4g evaluations/s/core\n", all);
  return 0;
}
