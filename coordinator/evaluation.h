#pragma once
// Classification accuracy of a forest on labelled frames (section 4): the confusion matrix
// between ground-truth part and most likely inferred part over body pixels, and the average
// per-class accuracy = mean of its row-normalized diagonal.

#include <cstdint>
#include <string>
#include <vector>

#include "runtime/core/forest.h"
#include "runtime/core/result.h"
#include "worker/image_source.h"

namespace poseforest::coordinator {

struct ConfusionMatrix {
  int num_parts = core::kNumParts;
  std::vector<uint64_t> counts;  ///< [truth * num_parts + predicted], pixels

  ConfusionMatrix() : counts(size_t(core::kNumParts) * core::kNumParts, 0) {}
  uint64_t TruthTotal(int part) const;
  /// Fraction of pixels of `part` classified as `part`; NaN if the part never occurs.
  double PartAccuracy(int part) const;
  /// Mean of PartAccuracy over parts that occur (the paper's metric).
  double AveragePerClassAccuracy() const;
  /// Fraction of all body pixels classified correctly.
  double PixelAccuracy() const;
  int PartsPresent() const;
  void Add(const ConfusionMatrix& other);
};

struct EvalOptions {
  int num_images = 50;
  uint64_t first_index = 0;  ///< frames first_index .. first_index + num_images - 1
  int threads = 0;           ///< 0 = all cores
};

/// Classifies every frame with runtime::Classifier and accumulates the confusion matrix over
/// body pixels (depth > 0 and a part label). Frames are independent of thread count.
core::Result<ConfusionMatrix> EvaluateForest(const core::Forest& forest, const worker::SourceSpec& source,
                                             const EvalOptions& options);

/// The per-part accuracy table and the confusion matrix (percent of each truth row) as text.
std::string FormatAccuracyTable(const ConfusionMatrix& m);
std::string FormatConfusionText(const ConfusionMatrix& m);
/// The row-normalized confusion matrix as an RGB picture (cell_px square cells, white = 100%,
/// diagonal tinted green, a border between parts).
core::Status WriteConfusionPng(const ConfusionMatrix& m, const std::string& path, int cell_px = 16);

}  // namespace poseforest::coordinator
