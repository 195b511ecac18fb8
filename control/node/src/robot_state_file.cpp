#include "reflex/control_node/robot_state_file.hpp"

#include "reflex/common/files.hpp"

#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

namespace reflex::control_node {

namespace {

constexpr char kMagic[4] = {'R', 'F', 'X', 'Q'};
constexpr std::uint32_t kVersion = 1;
constexpr std::size_t kHeaderSize = 40;     // bytes before q
constexpr std::uint32_t kMaxJoints = 4096;  // a sanity bound for a file of unknown origin
constexpr off_t kMaxFileSize = 2 * static_cast<off_t>(robotStateSlotSize(static_cast<int>(kMaxJoints)));

template <typename T>
T readAt(const unsigned char* p) {
  T v;
  std::memcpy(&v, p, sizeof(T));
  return v;
}
template <typename T>
void writeAt(unsigned char* p, T v) {
  std::memcpy(p, &v, sizeof(T));
}

std::string errnoText() { return std::strerror(errno); }

/// One slot as found in the file.
struct Slot {
  bool valid = false;
  std::string why;  ///< why it is not valid
  std::uint64_t seq = 0;
  std::uint32_t nq = 0;
  std::uint64_t hash = 0;
  std::int64_t wall_ns = 0;
  const unsigned char* q = nullptr;
};

Slot parseSlot(const std::vector<unsigned char>& file, std::size_t offset) {
  Slot s;
  if (file.size() < offset + 4) {
    s.why = "missing (file of " + std::to_string(file.size()) + " bytes)";
    return s;
  }
  const unsigned char* p = file.data() + offset;
  if (std::memcmp(p, kMagic, 4) != 0) {
    s.why = "no 'RFXQ' magic";
    return s;
  }
  if (file.size() < offset + kHeaderSize) {
    s.why = "truncated header (file of " + std::to_string(file.size()) + " bytes)";
    return s;
  }
  const auto version = readAt<std::uint32_t>(p + 4);
  if (version != kVersion) {
    s.why = "version " + std::to_string(version) + " (this program reads version 1)";
    return s;
  }
  s.nq = readAt<std::uint32_t>(p + 16);
  if (s.nq == 0 || s.nq > kMaxJoints) {
    s.why = "joint count " + std::to_string(s.nq) + " out of range";
    return s;
  }
  const std::size_t body = kHeaderSize + 8 * static_cast<std::size_t>(s.nq);
  if (file.size() < offset + body + 4) {
    s.why = "truncated (needs " + std::to_string(body + 8) + " bytes)";
    return s;
  }
  if (crc32(p, body) != readAt<std::uint32_t>(p + body)) {
    s.why = "CRC mismatch (torn or damaged)";
    return s;
  }
  s.valid = true;
  s.seq = readAt<std::uint64_t>(p + 8);
  s.hash = readAt<std::uint64_t>(p + 24);
  s.wall_ns = readAt<std::int64_t>(p + 32);
  s.q = p + kHeaderSize;
  return s;
}

std::string hex(std::uint64_t v) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%016llx", static_cast<unsigned long long>(v));
  return buf;
}

}  // namespace

std::uint64_t jointNamesHash(const std::vector<std::string>& q_names) {
  std::uint64_t h = 0xcbf29ce484222325ULL;
  auto add = [&](unsigned char c) {
    h ^= c;
    h *= 0x100000001b3ULL;
  };
  for (const auto& n : q_names) {
    for (const char c : n) add(static_cast<unsigned char>(c));
    add(0);
  }
  return h;
}

RobotStateFile::RobotStateFile(const std::string& path, const std::vector<std::string>& q_names,
                               const Eigen::VectorXd& q_lower, const Eigen::VectorXd& q_upper)
    : path_(path), nq_(static_cast<int>(q_names.size())), names_hash_(jointNamesHash(q_names)) {
  const std::string where = "robot state file '" + path + "'";
  if (nq_ <= 0 || q_lower.size() != nq_ || q_upper.size() != nq_)
    throw RobotStateError(where + ": the robot model has no joints or inconsistent limits");
  // Read back and rewritten in place: only a regular file (a device, a FIFO, a folder refused by name).
  if (const std::string why = common::inputFileProblem(path); !why.empty())
    throw RobotStateError("robot state file " + why);
  fd_ = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd_ < 0) throw RobotStateError("cannot open " + where + ": " + errnoText());
  try {
    if (::flock(fd_, LOCK_EX | LOCK_NB) != 0)
      throw RobotStateError(where + " is in use by another process (locked): " + errnoText());
    struct stat st {};
    if (::fstat(fd_, &st) != 0) throw RobotStateError("cannot stat " + where + ": " + errnoText());
    if (!S_ISREG(st.st_mode))
      throw RobotStateError(where + " is " + common::fileKind(st.st_mode) + ", not a regular file");
    if (st.st_size > kMaxFileSize)
      throw RobotStateError(where + ": " + std::to_string(st.st_size) + " bytes, too large to be a robot state file");
    std::vector<unsigned char> file(static_cast<std::size_t>(st.st_size));
    std::size_t got = 0;
    while (got < file.size()) {
      const ssize_t r = ::pread(fd_, file.data() + got, file.size() - got, static_cast<off_t>(got));
      if (r < 0 && errno == EINTR) continue;
      if (r <= 0) throw RobotStateError("cannot read " + where + ": " + (r < 0 ? errnoText() : "short read"));
      got += static_cast<std::size_t>(r);
    }
    if (!file.empty()) {
      // Slot 1 starts after slot 0: its size follows from slot 0's joint count if slot 0 is valid
      // (another robot's file), else from this robot's (a damaged slot 0 tells nothing).
      const Slot s0 = parseSlot(file, 0);
      const int nq0 = s0.valid ? static_cast<int>(s0.nq) : nq_;
      const Slot s1 = parseSlot(file, robotStateSlotSize(nq0));
      if (!s0.valid && !s1.valid)
        throw RobotStateError(where + " holds no valid robot state (slot 0: " + s0.why + "; slot 1: " + s1.why +
                              "); delete it to start from rest");
      const Slot& s = !s1.valid || (s0.valid && s0.seq > s1.seq) ? s0 : s1;
      if (s.nq != static_cast<std::uint32_t>(nq_) || s.hash != names_hash_)
        throw RobotStateError(where + " is the state of another robot (" + std::to_string(s.nq) +
                              " joints, joint-name hash " + hex(s.hash) + "; this robot: " + std::to_string(nq_) +
                              " joints, hash " + hex(names_hash_) + "); delete it to start from rest");
      q_loaded_.resize(nq_);
      for (int i = 0; i < nq_; ++i) {
        const double v = readAt<double>(s.q + 8 * static_cast<std::size_t>(i));
        if (!std::isfinite(v) || v < q_lower[i] - 1e-9 || v > q_upper[i] + 1e-9)
          throw RobotStateError(where + ": joint '" + q_names[static_cast<std::size_t>(i)] +
                                "' = " + std::to_string(v) + " is not finite or outside its limits [" +
                                std::to_string(q_lower[i]) + ", " + std::to_string(q_upper[i]) +
                                "]; delete the file to start from rest");
        q_loaded_[i] = std::min(std::max(v, q_lower[i]), q_upper[i]);
      }
      loaded_ = true;
      loaded_seq_ = seq_ = s.seq;
      loaded_wall_ns_ = s.wall_ns;
    }
  } catch (...) {
    ::close(fd_);
    fd_ = -1;
    throw;
  }
  record_.assign(robotStateSlotSize(nq_), 0);
  std::memcpy(record_.data(), kMagic, 4);
  writeAt<std::uint32_t>(record_.data() + 4, kVersion);
  writeAt<std::uint32_t>(record_.data() + 16, static_cast<std::uint32_t>(nq_));
  writeAt<std::uint64_t>(record_.data() + 24, names_hash_);
}

RobotStateFile::~RobotStateFile() {
  if (fd_ >= 0) ::close(fd_);  // also releases the lock
}

bool RobotStateFile::save(const Eigen::Ref<const Eigen::VectorXd>& q) noexcept {
  if (fd_ < 0 || q.size() != nq_) {
    ++write_errors_;
    return false;
  }
  const std::uint64_t seq = seq_ + 1;
  unsigned char* p = record_.data();
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  writeAt<std::uint64_t>(p + 8, seq);
  writeAt<std::int64_t>(p + 32, static_cast<std::int64_t>(ts.tv_sec) * 1000000000LL + ts.tv_nsec);
  for (int i = 0; i < nq_; ++i) writeAt<double>(p + kHeaderSize + 8 * static_cast<std::size_t>(i), q[i]);
  const std::size_t body = kHeaderSize + 8 * static_cast<std::size_t>(nq_);
  writeAt<std::uint32_t>(p + body, crc32(p, body));
  const off_t offset = static_cast<off_t>((seq & 1U) == 1U ? 0 : record_.size());
  ssize_t w;
  do {
    w = ::pwrite(fd_, p, record_.size(), offset);
  } while (w < 0 && errno == EINTR);
  if (w != static_cast<ssize_t>(record_.size())) {
    ++write_errors_;
    return false;
  }
  seq_ = seq;
  return true;
}

}  // namespace reflex::control_node
