#include "engine/evaluation.h"

// The figures of `eval` as text tables and images: joint AP, skeleton accuracy, part accuracy,
// the confusion matrix and precision-recall curves.

#include <cmath>
#include <cstdio>
#include <filesystem>

#include "runtime/image_io.h"
#include "runtime/visualize.h"

namespace poseforest::engine {

using core::ErrorCode;
using core::Status;

namespace {

// The ratio, or 0 when the bound is 0.
double Ratio(double a, double b) { return b > 0 ? a / b : 0.0; }
std::string RatioText(double r) {
  char c[16];
  std::snprintf(c, sizeof c, "%.2f", r);
  return c;
}

}  // namespace

std::string FormatSkeletonTable(const Evaluation& e) {
  const auto& a = e.skeleton;
  std::string out;
  char buf[640];
  std::snprintf(
      buf, sizeof buf,
      "skeleton accuracy (what `live` reports: per joint one position, tracked or not; %d one-person "
      "frames, D = %.2f m, confidence %s, %s fit):\n",
      a.frames, double(e.distance_m), e.calibrated ? "calibrated (JCAL)" : "the uncalibrated fallback",
      std::string(runtime::SkeletonFitName(a.fit)).c_str());
  out += buf;
  // Skeletons are scored on one-person frames only: with none, a table of zeros would read as
  // a forest that tracks nothing.
  if (a.frames == 0) return out + "(no figures: the test set has no one-person frames)\n";
  std::snprintf(buf, sizeof buf, "%-11s %8s %16s %16s %18s %14s %18s\n", "joint", "visible", "tracked within D",
                "tracked & right", "not tracked right", "found within", "hidden: in 0.15 m");
  out += buf;
  auto ratio = [](int n, int d) { return d ? double(n) / d : 0.0; };
  double within = 0, right = 0, untracked = 0, found = 0, hidden = 0;
  int joints = 0, untracked_joints = 0, tracked_joints = 0, hidden_joints = 0;
  for (int j = 0; j < core::kNumJoints; ++j) {
    const size_t k = size_t(j);
    auto cell = [&](int n, int d) {
      char c[32];
      if (d)
        std::snprintf(c, sizeof c, "%.3f (%d)", ratio(n, d), d);
      else
        std::snprintf(c, sizeof c, "- (0)");
      return std::string(c);
    };
    std::snprintf(buf, sizeof buf, "%-11s %8d %16s %16s %18s %14.3f %18s\n", std::string(core::JointName(j)).c_str(),
                  a.visible[k], cell(a.tracked_within[k], a.visible[k]).c_str(),
                  cell(a.tracked_right[k], a.tracked[k]).c_str(),
                  cell(a.untracked_invisible[k], a.untracked[k]).c_str(), ratio(a.found_within[k], a.visible[k]),
                  cell(a.hidden_within[k], a.hidden[k]).c_str());
    if (a.hidden[k]) hidden += ratio(a.hidden_within[k], a.hidden[k]), ++hidden_joints;
    out += buf;
    if (a.visible[k]) within += ratio(a.tracked_within[k], a.visible[k]), found += ratio(a.found_within[k], a.visible[k]), ++joints;
    if (a.tracked[k]) right += ratio(a.tracked_right[k], a.tracked[k]), ++tracked_joints;
    if (a.untracked[k]) untracked += ratio(a.untracked_invisible[k], a.untracked[k]), ++untracked_joints;
  }
  std::snprintf(
      buf, sizeof buf,
      "mean over joints: tracked within %.2f m when visible %.3f, tracked & right %.3f, not tracked right "
      "%.3f, found within %.3f, hidden placed within 0.15 m %.3f\n(columns: fraction (count): of the frames where the "
      "joint is visible / tracked / not tracked / hidden; found within: visible and the position, tracked or not, "
      "within D)\n",
      double(e.distance_m), joints ? within / joints : 0.0, tracked_joints ? right / tracked_joints : 0.0,
      untracked_joints ? untracked / untracked_joints : 0.0, joints ? found / joints : 0.0,
      hidden_joints ? hidden / hidden_joints : 0.0);
  out += buf;
  // Where the hidden joints are, pooled over joints: outside the picture, or inside it behind
  // something.
  int outside = 0, outside_within = 0, inside = 0, inside_within = 0;
  for (size_t k = 0; k < size_t(core::kNumJoints); ++k) {
    outside += a.hidden_outside[k], outside_within += a.hidden_outside_within[k];
    inside += a.hidden[k] - a.hidden_outside[k],
        inside_within += a.hidden_within[k] - a.hidden_outside_within[k];
  }
  if (outside + inside > 0) {
    std::snprintf(
        buf, sizeof buf,
        "hidden joints placed within 0.15 m, pooled: outside the picture %.3f (%d of %d), inside it "
        "behind something %.3f (%d of %d)\n",
        ratio(outside_within, outside), outside_within, outside, ratio(inside_within, inside), inside_within,
        inside);
    out += buf;
  }
  return out;
}

std::string FormatJointApTable(const Evaluation& e) {
  std::string s;
  char line[320];
  std::snprintf(
      line, sizeof line,
      "joint average precision (section 4: D = %.2f m, every proposal counts), %d frames, %d people;\n",
      double(e.distance_m), e.frames, e.people);
  s += line;
  // Each method's own parameter set, and where it came from.
  auto params_line = [&](const char* method, const core::ProposalParams& params,
                         core::ProposalParamsSource source, bool given) {
    double b = 0, lambda = 0, zeta = 0;
    for (const auto& p : params) b += p.bandwidth_m, lambda += p.prob_threshold, zeta += p.z_offset_m;
    std::snprintf(line, sizeof line,
                  "proposal parameters, %s: %s, mean b = %.3f m, lambda = %.3f, zeta = %.3f m\n", method,
                  given ? "given" : core::DescribeProposalParamsSource(source), b / core::kNumJoints,
                  lambda / core::kNumJoints, zeta / core::kNumJoints);
    s += line;
  };
  params_line(e.ran_upper_bound ? "mean shift (and gt-parts)" : "mean shift", e.params, e.params_source,
              e.params_given);
  if (e.ran_fast) params_line("fast clustering", e.fast_params, e.fast_params_source, e.fast_params_given);
  std::snprintf(line, sizeof line, "%-11s %9s %9s %9s %11s %9s\n", "joint", "visible", "AP mean", "AP fast",
                "AP gt-parts", "mean/gt");
  s += line;
  // A method that did not run prints "-", never a misleading 0.
  auto cell = [](bool ran, double v) {
    char c[16];
    if (ran)
      std::snprintf(c, sizeof c, "%.3f", v);
    else
      std::snprintf(c, sizeof c, "-");
    return std::string(c);
  };
  for (int j = 0; j < core::kNumJoints; ++j) {
    const double ms = e.mean_shift.AveragePrecision(j), up = e.upper_bound.AveragePrecision(j);
    std::snprintf(line, sizeof line, "%-11s %9d %9.3f %9s %11s %9s\n",
                  std::string(core::JointName(j)).c_str(), e.mean_shift.positives(j), ms,
                  cell(e.ran_fast, e.fast.AveragePrecision(j)).c_str(), cell(e.ran_upper_bound, up).c_str(),
                  e.ran_upper_bound ? RatioText(Ratio(ms, up)).c_str() : "-");
    s += line;
  }
  const double ms = e.mean_shift.MeanAveragePrecision(), up = e.upper_bound.MeanAveragePrecision();
  std::snprintf(line, sizeof line, "%-11s %9s %9.3f %9s %11s %9s\n", "mAP", "", ms,
                cell(e.ran_fast, e.fast.MeanAveragePrecision()).c_str(), cell(e.ran_upper_bound, up).c_str(),
                e.ran_upper_bound ? RatioText(Ratio(ms, up)).c_str() : "-");
  s += line;
  s += "mAP: mean shift " + cell(true, ms);
  if (e.ran_fast) s += ", fast clustering " + cell(true, e.fast.MeanAveragePrecision());
  if (e.ran_upper_bound) {
    std::snprintf(line, sizeof line, "; upper bound (ground-truth parts) %.3f; inferred / upper bound %.2f",
                  up, Ratio(ms, up));
    s += line;
  }
  s += "\n(the paper, synthetic test set: mean shift 0.731, fast 0.677)\n";
  return s;
}

Status WritePrCurves(const Evaluation& e, const std::string& dir) {
  if (!e.has_joints)
    return Status(ErrorCode::kInvalidArgument, "no joints in this test set: no precision-recall curves");
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) return Status(ErrorCode::kIo, dir + ": cannot create folder: " + ec.message());
  const core::Rgb blue{31, 119, 180}, orange{255, 127, 14}, green{44, 160, 44};
  std::vector<runtime::PrPanel> panels;
  for (int j = 0; j < core::kNumJoints; ++j) {
    runtime::PrPanel p{std::string(core::JointName(j)), {}};
    p.series.push_back({"mean shift", blue, e.mean_shift.Curve(j), e.mean_shift.AveragePrecision(j)});
    if (e.fast.positives(j))
      p.series.push_back({"fast", orange, e.fast.Curve(j), e.fast.AveragePrecision(j)});
    if (e.upper_bound.positives(j))
      p.series.push_back(
          {"gt parts (upper bound)", green, e.upper_bound.Curve(j), e.upper_bound.AveragePrecision(j)});
    panels.push_back(std::move(p));
  }
  const auto grid = runtime::PrCurvesFigure(panels, 4);
  POSEFOREST_RETURN_IF_ERROR(runtime::WriteRgbPng((std::filesystem::path(dir) / "pr_joints.png").string(),
                                                  grid.width, grid.height, grid.rgb));
  runtime::PrPanel mean{"mean over joints (mAP)", {}};
  mean.series.push_back({"mean shift", blue, e.mean_shift.MeanCurve(), e.mean_shift.MeanAveragePrecision()});
  if (e.fast.MeanAveragePrecision() > 0 || e.fast.positives(0))
    mean.series.push_back({"fast", orange, e.fast.MeanCurve(), e.fast.MeanAveragePrecision()});
  if (e.upper_bound.positives(0) || e.upper_bound.MeanAveragePrecision() > 0)
    mean.series.push_back(
        {"gt parts (upper bound)", green, e.upper_bound.MeanCurve(), e.upper_bound.MeanAveragePrecision()});
  const auto big = runtime::PrCurvesFigure({mean}, 1, 720, 540, 2);
  return runtime::WriteRgbPng((std::filesystem::path(dir) / "pr_mean.png").string(), big.width, big.height,
                              big.rgb);
}

std::string FormatAccuracyTable(const ConfusionMatrix& m) {
  std::string s = "part            pixels   accuracy\n";
  char line[96];
  for (int c = 0; c < m.num_parts; ++c) {
    const uint64_t n = m.TruthTotal(c);
    if (n == 0) {
      std::snprintf(line, sizeof(line), "%-12s %9s   %8s\n", std::string(core::PartName(c)).c_str(), "0",
                    "-");
    } else {
      std::snprintf(line, sizeof(line), "%-12s %9llu   %7.2f%%\n", std::string(core::PartName(c)).c_str(),
                    static_cast<unsigned long long>(n), 100.0 * m.PartAccuracy(c));
    }
    s += line;
  }
  std::snprintf(line, sizeof(line),
                "average per-class accuracy: %.2f%% over %d parts (pixel accuracy %.2f%%)\n",
                100.0 * m.AveragePerClassAccuracy(), m.PartsPresent(), 100.0 * m.PixelAccuracy());
  s += line;
  return s;
}

std::string FormatConfusionText(const ConfusionMatrix& m) {
  // Rows: truth; columns: predicted part index; entries: percent of the row, rounded.
  std::string s = "confusion (rows = truth, columns = predicted part index, % of row)\n          ";
  char cell[32];
  for (int p = 0; p < m.num_parts; ++p) {
    std::snprintf(cell, sizeof(cell), "%4d", p);
    s += cell;
  }
  s += "\n";
  for (int t = 0; t < m.num_parts; ++t) {
    std::snprintf(cell, sizeof(cell), "%2d %-7.7s", t, std::string(core::PartName(t)).c_str());
    s += cell;
    const uint64_t n = m.TruthTotal(t);
    for (int p = 0; p < m.num_parts; ++p) {
      if (n == 0) {
        s += "   .";
        continue;
      }
      const double pct = 100.0 * double(m.counts[size_t(t * m.num_parts + p)]) / double(n);
      if (m.counts[size_t(t * m.num_parts + p)] == 0)
        s += "   .";
      else {
        std::snprintf(cell, sizeof(cell), "%4.0f", pct);
        s += cell;
      }
    }
    s += "\n";
  }
  return s;
}

core::Status WriteConfusionPng(const ConfusionMatrix& m, const std::string& path, int cell_px) {
  const int n = m.num_parts, size = n * cell_px + 1;
  std::vector<uint8_t> rgb(static_cast<size_t>(size) * size_t(size) * 3, 64);  // grid lines: dark grey
  for (int t = 0; t < n; ++t) {
    const uint64_t total = m.TruthTotal(t);
    for (int p = 0; p < n; ++p) {
      const double f = total ? double(m.counts[size_t(t * n + p)]) / double(total) : 0.0;
      const auto v = uint8_t(std::lround(255.0 * std::sqrt(f)));  // sqrt: small confusions visible
      const uint8_t r = t == p ? uint8_t(v / 2) : v, g = v, b = t == p ? uint8_t(v / 2) : v;
      for (int y = t * cell_px + 1; y < (t + 1) * cell_px; ++y)
        for (int x = p * cell_px + 1; x < (p + 1) * cell_px; ++x) {
          uint8_t* px = &rgb[(size_t(y) * size_t(size) + size_t(x)) * 3];
          px[0] = r;
          px[1] = g;
          px[2] = b;
        }
    }
  }
  return runtime::WriteRgbPng(path, size, size, rgb);
}

}  // namespace poseforest::engine
