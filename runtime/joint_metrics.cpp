#include "runtime/joint_metrics.h"

#include <algorithm>

namespace poseforest::runtime {

void JointApEvaluator::AddFrame(const FrameProposals& proposals, const std::vector<PersonJoints>& people) {
  for (int j = 0; j < core::kNumJoints; ++j) {
    for (const PersonJoints& person : people) positives_[size_t(j)] += person.visible[size_t(j)];
    std::vector<const JointProposal*> ranked;
    for (const JointProposal& p : proposals[size_t(j)]) ranked.push_back(&p);
    std::stable_sort(ranked.begin(), ranked.end(), [](const JointProposal* a, const JointProposal* b) {
      return a->confidence > b->confidence;
    });
    std::vector<uint8_t> matched(people.size(), 0);
    for (const JointProposal* p : ranked) {
      // The nearest unmatched visible joint within D makes it a true positive.
      int best = -1;
      float best_d = distance_;
      bool near_matched = false, near_invisible = false;
      for (size_t k = 0; k < people.size(); ++k) {
        const float d = (people[k].position[size_t(j)] - p->position).norm();
        if (!(d <= distance_)) continue;
        if (!people[k].visible[size_t(j)]) {
          near_invisible = true;
        } else if (matched[k]) {
          near_matched = true;
        } else if (d <= best_d) {
          best = int(k);
          best_d = d;
        }
      }
      if (best >= 0) {
        matched[size_t(best)] = 1;
        scored_[size_t(j)].push_back({p->confidence, true});
      } else if (near_invisible && !near_matched) {
        // Neither way: the joint is not visible, so it is not penalized or rewarded.
      } else {
        scored_[size_t(j)].push_back({p->confidence, false});  // duplicate, or nothing within D
      }
    }
  }
}

std::vector<PrPoint> JointApEvaluator::Curve(int joint) const {
  std::vector<Scored> s = scored_[size_t(joint)];
  std::stable_sort(s.begin(), s.end(),
                   [](const Scored& a, const Scored& b) { return a.confidence > b.confidence; });
  std::vector<PrPoint> curve;
  const int pos = positives_[size_t(joint)];
  int tp = 0, fp = 0;
  for (size_t i = 0; i < s.size(); ++i) {
    (s[i].true_positive ? tp : fp)++;
    // One point per distinct threshold (equal confidences enter together).
    if (i + 1 < s.size() && s[i + 1].confidence == s[i].confidence) continue;
    curve.push_back({s[i].confidence, double(tp) / double(tp + fp), pos > 0 ? double(tp) / pos : 0.0});
  }
  return curve;
}

double JointApEvaluator::AveragePrecision(int joint) const {
  if (positives_[size_t(joint)] == 0) return 0.0;
  std::vector<PrPoint> curve = Curve(joint);
  // All-point interpolation: precision made monotone from the right, integrated over recall.
  for (size_t i = curve.size(); i-- > 1;)
    curve[i - 1].precision = std::max(curve[i - 1].precision, curve[i].precision);
  double ap = 0, last_recall = 0;
  for (const PrPoint& p : curve) {
    ap += (p.recall - last_recall) * p.precision;
    last_recall = p.recall;
  }
  return ap;
}

double JointApEvaluator::MeanAveragePrecision() const {
  double sum = 0;
  int n = 0;
  for (int j = 0; j < core::kNumJoints; ++j)
    if (positives_[size_t(j)] > 0) sum += AveragePrecision(j), ++n;
  return n ? sum / n : 0.0;
}

std::vector<PrPoint> JointApEvaluator::MeanCurve(int levels) const {
  levels = std::max(levels, 2);
  std::vector<PrPoint> mean(static_cast<size_t>(levels));
  for (int i = 0; i < levels; ++i) mean[size_t(i)] = {0.0f, 0.0, double(i) / double(levels - 1)};
  int n = 0;
  for (int j = 0; j < core::kNumJoints; ++j) {
    if (positives_[size_t(j)] == 0) continue;
    ++n;
    std::vector<PrPoint> curve = Curve(j);
    for (size_t i = curve.size(); i-- > 1;)
      curve[i - 1].precision = std::max(curve[i - 1].precision, curve[i].precision);
    size_t k = 0;
    for (PrPoint& m : mean) {
      while (k < curve.size() && curve[k].recall < m.recall - 1e-12) ++k;
      if (k < curve.size()) m.precision += curve[k].precision;
    }
  }
  if (n > 0)
    for (PrPoint& m : mean) m.precision /= n;
  return mean;
}

}  // namespace poseforest::runtime
