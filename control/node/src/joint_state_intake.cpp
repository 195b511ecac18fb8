// The named-joint state checks (joint_state_intake.hpp).
#include "reflex/control_node/joint_state_intake.hpp"

#include "reflex/control/onboard.hpp"

#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>

namespace reflex::control_node {

namespace {

/// "01.0f.a3.…|0.0.3.3": the writer GUID's participant prefix (12 bytes) and entity id (4 bytes).
void formatGuid(const std::array<unsigned char, 16>& g, char (&out)[64]) noexcept {
  std::snprintf(out, sizeof(out), "%02x.%02x.%02x.%02x.%02x.%02x.%02x.%02x.%02x.%02x.%02x.%02x|%x.%x.%x.%x", g[0], g[1],
                g[2], g[3], g[4], g[5], g[6], g[7], g[8], g[9], g[10], g[11], g[12], g[13], g[14], g[15]);
}

}  // namespace

JointStateIntake::JointStateIntake(const control::Model& model, const Options& options)
    : model_(model), options_(options) {
  index_.assign(static_cast<std::size_t>(model.nq), -1);
  q_.setZero(model.nq);
  control::acceptedStateRange(model, options.period, lower_, upper_);
}

bool JointStateIntake::take(const View& s, const bus::dds::SampleInfo& info, std::int64_t now_ns) noexcept {
  Guid writer;
  const unsigned char* handle = info.publication_handle.value;  // 16 bytes: the writer GUID
  std::copy(handle, handle + writer.size(), writer.begin());
  // Secure mode: only a writer authenticated as "robot" can be bound (checked once per new writer:
  // identify() allocates, so a flood of one writer costs one check).
  if (options_.identities != nullptr && (!identity_checked_ || writer != candidate_)) {
    identity_checked_ = true;
    candidate_ = writer;
    try {
      candidate_ok_ = options_.identities->identify(info) == "robot";
    } catch (...) {
      candidate_ok_ = false;
    }
  }
  return accept(s, writer, now_ns);
}

bool JointStateIntake::reject(int cause, std::uint64_t& counter) noexcept {
  ++counter;
  cause_ = cause;
  texts_.keep(cause, rejection_);
  return false;
}

bool JointStateIntake::accept(const View& s, const Guid& writer, std::int64_t now_ns) noexcept {
  const auto seq = static_cast<unsigned long long>(s.seq);
  const char* what = options_.sample_name.c_str();
  // One robot writer (see the header): another writer is ignored while the bound one is alive.
  const bool bound_alive = bound_ && static_cast<double>(now_ns - writer_last_ns_) <= options_.rebind_silence * 1e9;
  const bool from_bound = bound_ && writer == robot_writer_;
  const bool identity_ok = options_.identities == nullptr || (writer == candidate_ && candidate_ok_);
  if ((bound_alive && !from_bound) || !identity_ok) {
    if (writer != other_ || other_text_[0] == '\0') {
      other_ = writer;
      formatGuid(writer, other_text_);
    }
    std::snprintf(rejection_, sizeof(rejection_), "%s %llu ignored: written by %s, not the robot writer %s%s", what,
                  seq, other_text_, bound_ ? bound_text_ : "(none bound yet)",
                  identity_ok ? "" : " (not authenticated as the identity 'robot')");
    return reject(kCauseOtherWriter, counts_.rejected_other_writer);
  }
  if (from_bound) writer_last_ns_ = now_ns;
  const std::size_t n = s.names.size();
  const bool no_velocities = options_.velocities_optional && s.velocities.empty();
  if (s.positions.size() != n || (s.velocities.size() != n && !no_velocities) ||
      (!s.efforts.empty() && s.efforts.size() != n)) {
    std::snprintf(rejection_, sizeof(rejection_),
                  "%s %llu rejected: %zu names but %zu positions, %zu velocities, %zu efforts", what, seq, n,
                  s.positions.size(), s.velocities.size(), s.efforts.size());
    return reject(0, counts_.rejected_length);
  }
  // The name map, built again only when the robot's list changes (comparing is allocation-free).
  bool same = robot_names_.size() == n;
  for (std::size_t k = 0; same && k < n; ++k) same = robot_names_[k] == s.names[k];
  if (!same) {
    robot_names_ = s.names;  // a new list: the one allocation, once per change of the robot's joints
    duplicate_ = -1;
    for (std::size_t k = 1; k < n && duplicate_ < 0; ++k)
      for (std::size_t j = 0; j < k; ++j)
        if (robot_names_[j] == robot_names_[k]) {
          duplicate_ = static_cast<int>(k);
          break;
        }
    for (int i = 0; i < model_.nq; ++i) {
      index_[static_cast<std::size_t>(i)] = -1;
      for (std::size_t k = 0; k < n; ++k)
        if (robot_names_[k] == model_.q_names[i]) index_[static_cast<std::size_t>(i)] = static_cast<int>(k);
    }
  }
  if (duplicate_ >= 0) {
    std::snprintf(rejection_, sizeof(rejection_), "%s %llu rejected: joint '%.100s' is listed twice", what, seq,
                  robot_names_[static_cast<std::size_t>(duplicate_)].c_str());
    return reject(5, counts_.rejected_duplicate);
  }
  for (int i = 0; i < model_.nq; ++i) {
    const int k = index_[static_cast<std::size_t>(i)];
    if (k < 0) {
      std::snprintf(rejection_, sizeof(rejection_), "%s %llu rejected: joint '%s' is missing", what, seq,
                    model_.q_names[i].c_str());
      return reject(1, counts_.rejected_missing);
    }
    const double p = s.positions[static_cast<std::size_t>(k)];
    const double v = no_velocities ? 0.0 : s.velocities[static_cast<std::size_t>(k)];
    if (!std::isfinite(p) || !std::isfinite(v)) {
      std::snprintf(rejection_, sizeof(rejection_), "%s %llu rejected: joint '%s' position %g velocity %g", what, seq,
                    model_.q_names[i].c_str(), p, v);
      return reject(2, counts_.rejected_non_finite);
    }
    // !(lo <= p && p <= hi): outside the accepted range (limits + one cycle at v_max; see the header).
    if (!(lower_[i] <= p && p <= upper_[i])) {
      std::snprintf(rejection_, sizeof(rejection_),
                    "%s %llu rejected: joint '%s' position %.6g outside its limits [%.6g, %.6g] "
                    "(accepted up to %.4g past a limit: v_max * period)",
                    what, seq, model_.q_names[i].c_str(), p, model_.q_lower[i], model_.q_upper[i],
                    control::stateLimitTolerance(model_, i, options_.period));
      return reject(6, counts_.rejected_limits);
    }
  }
  const std::int64_t ahead = s.stamp_ns - now_ns;
  if (static_cast<double>(ahead) > kFutureTolerance * 1e9) {
    std::snprintf(rejection_, sizeof(rejection_), "%s %llu rejected: stamped %.1f ms in the future (tolerance %.1f ms)",
                  what, seq, static_cast<double>(ahead) * 1e-6, kFutureTolerance * 1e3);
    return reject(3, counts_.rejected_future);
  }
  // A state of a newly bound writer (a restarted driver) starts its own stamp sequence.
  if (have_state_ && from_bound && s.stamp_ns <= state_stamp_ns_) {
    std::snprintf(rejection_, sizeof(rejection_), "%s %llu rejected: stamp not newer than %s %llu's", what, seq, what,
                  static_cast<unsigned long long>(state_seq_));
    return reject(4, counts_.rejected_old);
  }
  if (!from_bound) {  // the first accepted state of this writer: bind it
    if (bound_) ++counts_.writer_changes;
    bound_ = true;
    robot_writer_ = writer;
    writer_last_ns_ = now_ns;
    formatGuid(writer, bound_text_);
  }
  for (int i = 0; i < model_.nq; ++i)
    q_[i] = s.positions[static_cast<std::size_t>(index_[static_cast<std::size_t>(i)])];
  // The robot's interval: two consecutive accepted states of one writer (a new writer starts unknown).
  state_interval_ns_ = have_state_ && from_bound ? s.stamp_ns - state_stamp_ns_ : 0;
  have_state_ = true;
  state_seq_ = s.seq;
  state_stamp_ns_ = s.stamp_ns;
  ++counts_.accepted;
  return true;
}

double JointStateIntake::stateAge() const noexcept {
  if (!have_state_) return std::numeric_limits<double>::infinity();
  return static_cast<double>(bus::nowNs() - state_stamp_ns_) * 1e-9;
}

const Eigen::VectorXd* JointStateIntake::measuredPositions() const noexcept {
  if (!have_state_ || !(stateAge() <= options_.timeout)) return nullptr;
  return &q_;
}

}  // namespace reflex::control_node
