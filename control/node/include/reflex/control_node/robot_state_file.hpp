// The simulated robot's joint positions, kept in a file that outlives the controller process
// (reflex_controller --robot-state FILE). It emulates what real hardware gives for free: when the
// controller process dies the joints stay where they are, and a new controller starts from the
// measured positions instead of from rest (so a restart does not make the arms jump).
//
// Format (host byte order, little-endian on every supported machine): two fixed-size slots, each one
// complete record of one controller cycle, written alternately (slot = sequence & 1) with one pwrite:
//
//   offset  size   field
//        0     4   magic "RFXQ"
//        4     4   version (1)
//        8     8   sequence (1 for the first record of a file, +1 per record)
//       16     4   nq (number of joints)
//       20     4   reserved (0)
//       24     8   joint-name hash: FNV-1a 64 of the joint names in q order, each followed by '\0'
//       32     8   wall time of the write (CLOCK_REALTIME, ns since the Unix epoch)
//       40  8*nq   q (rad or m, the model's q order)
//  40+8*nq     4   CRC-32 (IEEE 802.3) of bytes [0, 40 + 8 nq)
//  44+8*nq     4   reserved (0)
//
// A kill -9 in the middle of a write can tear at most the slot being written; the other slot holds
// the previous cycle. The loader takes the valid slot (magic, version, CRC) with the highest sequence.
// The data survive the death of the process (page cache), not a power loss: nothing is fsync'ed from
// the control loop (an fsync can block for milliseconds).
//
// Start-up policy: no file, or an empty one -> no saved state (the caller starts from rest and the
// file is created). A file with content that is not a valid state of THIS robot (no valid slot,
// another joint count or joint-name hash, a position that is not finite or outside the joint limits)
// -> RobotStateError naming the file and the reason; the controller refuses to start rather than
// guess where the joints are. Delete the file to start from rest on purpose. The file is locked
// (flock) while open, so two controllers can never drive one robot state.
#pragma once

#include "reflex/common/error.hpp"
#include "reflex/common/crc32.hpp"

#include <Eigen/Core>

#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

namespace reflex::control_node {

class RobotStateError : public reflex::Error {
 public:
  using reflex::Error::Error;
};

/// FNV-1a 64 of the joint names in order, each followed by '\0' (the identity of a robot's joint set).
std::uint64_t jointNamesHash(const std::vector<std::string>& q_names);

/// CRC-32 (IEEE 802.3): the project's one implementation (reflex/common/crc32.hpp).
using common::crc32;

/// Size in bytes of one slot for nq joints.
constexpr std::size_t robotStateSlotSize(int nq) { return 48 + 8 * static_cast<std::size_t>(nq); }

class RobotStateFile {
 public:
  /// Opens or creates `path` for a robot with these joints and limits and reads the saved state.
  /// Throws RobotStateError naming the file on an I/O error, a lock held by another process, or
  /// content that is not a valid state of this robot (see the policy above).
  RobotStateFile(const std::string& path, const std::vector<std::string>& q_names, const Eigen::VectorXd& q_lower,
                 const Eigen::VectorXd& q_upper);
  ~RobotStateFile();
  RobotStateFile(const RobotStateFile&) = delete;
  RobotStateFile& operator=(const RobotStateFile&) = delete;

  const std::string& path() const { return path_; }
  /// True if the file held a valid state of this robot; then loadedPositions() is it.
  bool loaded() const { return loaded_; }
  const Eigen::VectorXd& loadedPositions() const { return q_loaded_; }
  std::uint64_t loadedSequence() const { return loaded_seq_; }
  std::int64_t loadedWallNs() const { return loaded_wall_ns_; }

  /// Writes q (size nq) as the next record. For the control loop: allocation-free, never throws.
  /// Returns false (and counts it) if the write failed or was short; the robot state then stays at
  /// the last complete record.
  bool save(const Eigen::Ref<const Eigen::VectorXd>& q) noexcept;
  std::uint64_t writeErrors() const { return write_errors_; }
  std::uint64_t sequence() const { return seq_; }

 private:
  std::string path_;
  int fd_ = -1;
  int nq_ = 0;
  std::uint64_t names_hash_ = 0;
  std::uint64_t seq_ = 0;  ///< of the last record written (or loaded)
  std::uint64_t write_errors_ = 0;
  bool loaded_ = false;
  Eigen::VectorXd q_loaded_;
  std::uint64_t loaded_seq_ = 0;
  std::int64_t loaded_wall_ns_ = 0;
  std::vector<unsigned char> record_;  ///< one slot, preallocated
};

}  // namespace reflex::control_node
