#pragma once
// The coordinator's side of the conversation with its workers. Everything it hears goes
// through Pump: presence to the worker registry, replies to the round that is open,
// SubtreeResults to the subtree scheduler, offenders and silent workers dropped. Round sends
// one LevelRequest (a ranges, histograms, counts or frames request) to the assigned workers and
// pumps until each has answered; a worker lost meanwhile has its frames handed on and the
// round is asked again under a new epoch.

#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include "coordinator/session.h"
#include "coordinator/worker_registry.h"
#include "poseforest/v1/wire.pb.h"
#include "runtime/core/result.h"

namespace poseforest::coordinator {

struct Reply {
  std::string sender;
  v1::HistogramReply body;
};

class Rounds {
 public:
  Rounds(Session& session, WorkerRegistry& registry);

  /// Where SubtreeResults go (the subtree scheduler); set before the first Pump.
  std::function<void(const std::string& sender, const v1::SubtreeResult&)> on_subtree_result;

  /// Receives for up to `timeout`, handling presence, replies, events, offenders and timeouts.
  /// Replies of `want_epoch` from pending workers land in `replies`.
  void Pump(std::chrono::milliseconds timeout, uint64_t want_epoch = 0,
            std::map<std::string, Reply>* replies = nullptr);

  /// One request/reply round over the assigned workers, repeated under a new epoch (after
  /// handing lost workers' frames on) until every assigned worker has answered.
  core::Result<std::vector<Reply>> Round(v1::Phase phase, const std::vector<uint32_t>& node_ids,
                                         const std::vector<v1::NodeSpec>& specs, int level);

 private:
  /// A reply that is well-formed for the gate but not what the open round asked: an error.
  core::Status CheckShape(const Reply& r, const std::string& sender) const;
  /// A HistogramReply: kept in `replies` if it answers the open round.
  void OnHistogramReply(const std::string& sender, const v1::HistogramReply& body, size_t bytes,
                        uint64_t want_epoch, std::map<std::string, Reply>* replies);
  /// The replies of a finished round, in worker order; its time goes to the level's split.
  std::vector<Reply> CloseRound(std::map<std::string, Reply>& replies, double t_round);

  Session& s_;
  WorkerRegistry& registry_;
  v1::Phase expected_phase_ = v1::PHASE_UNSPECIFIED;
  int expected_nodes_ = 0;
};

}  // namespace poseforest::coordinator
