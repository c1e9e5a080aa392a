#include "coordinator/evaluation.h"

#include <omp.h>

#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>

#include "runtime/classifier.h"
#include "runtime/image_io.h"

namespace poseforest::coordinator {

uint64_t ConfusionMatrix::TruthTotal(int part) const {
  uint64_t n = 0;
  for (int p = 0; p < num_parts; ++p) n += counts[size_t(part * num_parts + p)];
  return n;
}

double ConfusionMatrix::PartAccuracy(int part) const {
  const uint64_t n = TruthTotal(part);
  if (n == 0) return std::numeric_limits<double>::quiet_NaN();
  return double(counts[size_t(part * num_parts + part)]) / double(n);
}

double ConfusionMatrix::AveragePerClassAccuracy() const {
  double sum = 0;
  int k = 0;
  for (int c = 0; c < num_parts; ++c) {
    const double a = PartAccuracy(c);
    if (std::isnan(a)) continue;
    sum += a;
    ++k;
  }
  return k ? sum / k : std::numeric_limits<double>::quiet_NaN();
}

double ConfusionMatrix::PixelAccuracy() const {
  uint64_t right = 0, all = 0;
  for (int c = 0; c < num_parts; ++c) {
    right += counts[size_t(c * num_parts + c)];
    all += TruthTotal(c);
  }
  return all ? double(right) / double(all) : std::numeric_limits<double>::quiet_NaN();
}

int ConfusionMatrix::PartsPresent() const {
  int k = 0;
  for (int c = 0; c < num_parts; ++c) k += TruthTotal(c) > 0;
  return k;
}

void ConfusionMatrix::Add(const ConfusionMatrix& other) {
  for (size_t i = 0; i < counts.size(); ++i) counts[i] += other.counts[i];
}

core::Result<ConfusionMatrix> EvaluateForest(const core::Forest& forest, const worker::SourceSpec& source,
                                             const EvalOptions& options) {
  if (forest.num_parts != core::kNumParts)
    return core::Status(
        core::ErrorCode::kInvalidArgument,
        "forest has " + std::to_string(forest.num_parts) + " parts; evaluation needs the 31-part taxonomy");
  auto src = worker::MakeImageSource(source);
  if (!src.ok()) return src.status();
  runtime::Classifier classifier(forest);
  runtime::ClassifyOptions copt;
  copt.num_threads = options.threads;
  runtime::Classification out;
  ConfusionMatrix m;
  for (int i = 0; i < options.num_images; ++i) {
    auto frame = (*src)->Frame(options.first_index + uint64_t(i));
    if (!frame.ok()) return frame.status();
    classifier.Classify(frame->depth, copt, &out);
    for (size_t p = 0; p < frame->depth.pixels.size(); ++p) {
      const uint8_t truth = frame->labels.pixels[p];
      if (frame->depth.pixels[p] == 0 || truth >= core::kNumParts) continue;
      const uint8_t pred = out.labels.pixels[p];
      if (pred >= core::kNumParts) continue;  // cannot happen for a foreground pixel
      ++m.counts[size_t(truth) * core::kNumParts + pred];
    }
  }
  return m;
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

}  // namespace poseforest::coordinator
