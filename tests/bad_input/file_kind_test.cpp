// Issue 16, item 11: a file argument that is not a regular file -- a FIFO (mkfifo), a character
// device (/dev/zero), a directory -- is refused at once, with an error that names the path and what it
// is, by every loader of a file a user names (and by the tools that take such files). The old loaders
// blocked forever on a FIFO (open(2) waits for a writer) and read /dev/zero without end.
//
// Independent answer: each call runs in a child process with a deadline of one second; the child
// reports whether the loader threw its documented error type with the path and the kind ("is a FIFO
// (named pipe)", "is a character device", "is a directory") in the message. A blocked child is killed
// and the case fails. Tools: the real executables under `timeout`, exit status and stderr checked.
#include "reflex/bus/error.hpp"
#include "reflex/bus/participant.hpp"
#include "reflex/control/controller.hpp"
#include "reflex/control/urdf_loader.hpp"
#include "reflex/modules/config.hpp"
#include "reflex/modules/scripted.hpp"
#include "reflex/record/record_file.hpp"
#include "reflex/vision/calibration.hpp"
#include "reflex/vision/error.hpp"
#include "reflex/vision/object_map.hpp"
#include "reflex/vision/session.hpp"

#include <gtest/gtest.h>

#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>
#include <thread>
#include <vector>

namespace {

namespace fs = std::filesystem;

/// A fresh folder holding a FIFO and a directory, plus /dev/zero: the three kinds of non-file.
struct NonFiles {
  std::string dir, fifo, folder;
  NonFiles() {
    std::string templ = ::testing::TempDir() + "reflex_file_kind_XXXXXX";
    if (!mkdtemp(templ.data())) throw std::runtime_error("mkdtemp failed");
    dir = templ;
    fifo = dir + "/input.fifo";
    folder = dir + "/a_folder.yaml";
    if (mkfifo(fifo.c_str(), 0600) != 0) throw std::runtime_error("mkfifo failed");
    fs::create_directories(folder);
  }
  ~NonFiles() {
    std::error_code ec;
    fs::remove_all(dir, ec);
  }
  std::vector<std::pair<std::string, std::string>> cases() const {
    return {{fifo, "is a FIFO (named pipe)"}, {"/dev/zero", "is a character device"}, {folder, "is a directory"}};
  }
};

/// 0: threw E naming path and kind; 2: returned; 3: threw E without them; 4: threw something else.
template <class E>
int classify(const std::function<void()>& load, const std::string& path, const std::string& kind) {
  try {
    load();
    return 2;
  } catch (const E& e) {
    const std::string what = e.what();
    if (what.find(path) != std::string::npos && what.find(kind) != std::string::npos) return 0;
    std::fprintf(stderr, "message without '%s' / '%s': %s\n", path.c_str(), kind.c_str(), e.what());
    return 3;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "other exception: %s\n", e.what());
    return 4;
  }
}

/// Runs `fn` (returning an exit status) in a child; -1 if it did not finish within `seconds`.
int inChild(double seconds, const std::function<int()>& fn) {
  const pid_t pid = fork();
  if (pid == 0) _exit(fn());
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  int status = 0;
  while (waitpid(pid, &status, WNOHANG) == 0) {
    if (std::chrono::steady_clock::now() > deadline) {
      kill(pid, SIGKILL);
      waitpid(pid, &status, 0);
      return -1;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  return WIFEXITED(status) ? WEXITSTATUS(status) : 100 + WTERMSIG(status);
}

struct Loader {
  const char* name;
  std::function<int(const std::string& path, const std::string& kind)> run;
};

template <class E>
Loader loader(const char* name, std::function<void(const std::string&)> load) {
  return {name, [load](const std::string& path, const std::string& kind) {
            return classify<E>([&] { load(path); }, path, kind);
          }};
}

TEST(FileKind, EveryLoaderRefusesAFifoADeviceAndAFolderWithinASecond) {
  using reflex::control::ModelError;
  const NonFiles nf;
  const std::vector<Loader> loaders = {
      loader<ModelError>("URDF", [](const std::string& p) { reflex::control::loadModel(p, {}); }),
      loader<ModelError>("collision YAML", [](const std::string& p) { reflex::control::loadCollisionConfig(p); }),
      loader<reflex::control::ConfigError>("controller YAML",
                                           [](const std::string& p) { reflex::control::loadControllerConfig(p); }),
      loader<reflex::modules::ConfigError>("behavior YAML",
                                           [](const std::string& p) { reflex::modules::ConfigNode::loadFile(p); }),
      loader<reflex::modules::ConfigError>("timeline CSV",
                                           [](const std::string& p) { reflex::modules::readTimelineCsv(p); }),
      loader<reflex::record::RecordError>("recording", [](const std::string& p) { reflex::record::RecordReader r(p); }),
      loader<reflex::bus::BusError>("DDS profiles XML",
                                    [](const std::string& p) {
                                      reflex::bus::BusConfig c;
                                      c.module_name = "file_kind_test";
                                      c.domain_id = 0;
                                      c.profiles_file = p;
                                      reflex::bus::Participant participant(c);
                                    }),
      loader<reflex::vision::VisionError>("camera calibration",
                                          [](const std::string& p) { reflex::vision::loadCameraInfo(p); }),
      loader<reflex::vision::VisionError>("camera mount", [](const std::string& p) { reflex::vision::loadCameraMount(p); }),
      loader<reflex::vision::VisionError>("object map", [](const std::string& p) { reflex::vision::loadObjectMap(p); }),
      loader<reflex::vision::VisionError>("timestamps CSV", [](const std::string& p) { reflex::vision::loadTimestamps(p); }),
      loader<reflex::vision::VisionError>("ground truth CSV",
                                          [](const std::string& p) { reflex::vision::loadGroundTruth(p); }),
  };
  for (const Loader& l : loaders) {
    for (const auto& [path, kind] : nf.cases()) {
      const int status = inChild(1.0, [&, p = path, k = kind] { return l.run(p, k); });
      EXPECT_EQ(status, 0) << l.name << " given " << path << " (" << kind << "): "
                           << (status == -1 ? "still blocked after 1 s" : "status " + std::to_string(status));
    }
  }
}

TEST(FileKind, TheCollisionFileNextToTheUrdfIsNotOpenedBlindly) {
  // Every tool probed <robot>.collision.yaml with std::ifstream(...).good(): that open blocks on a FIFO.
  const NonFiles nf;
  const std::string urdf = nf.dir + "/robot.urdf";
  fs::copy_file(std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/asimo_like.urdf", urdf);
  const std::string coll = nf.dir + "/robot.collision.yaml";
  ASSERT_EQ(mkfifo(coll.c_str(), 0600), 0);
  const int status = inChild(1.0, [&] {
    return classify<reflex::control::ModelError>([&] { reflex::control::loadCollisionConfigFor(urdf, ""); }, coll,
                                                 "is a FIFO");
  });
  EXPECT_EQ(status, 0) << (status == -1 ? "blocked" : std::to_string(status));
  // Nothing there: the defaults, as before.
  fs::remove(coll);
  EXPECT_TRUE(reflex::control::loadCollisionConfigFor(urdf, "").exclude.empty());
}

/// Runs a shell command under `timeout 5`; returns its exit status and stderr.
std::pair<int, std::string> runTool(const std::string& cmd) {
  const std::string full = "timeout -s KILL 5 " + cmd + " 2>&1 >/dev/null";
  FILE* p = popen(full.c_str(), "r");
  std::string out;
  std::array<char, 512> buf{};
  while (p && fgets(buf.data(), buf.size(), p)) out += buf.data();
  const int st = p ? pclose(p) : -1;
  return {WIFEXITED(st) ? WEXITSTATUS(st) : -1, out};
}

TEST(FileKind, ToolsExitWithAnErrorNamingThePathInsteadOfHanging) {
  const NonFiles nf;
  const std::string bin = REFLEX_BIN_DIR;
  const std::string urdf = std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/asimo_like.urdf";
  const std::vector<std::string> commands = {
      bin + "/reflex_record info " + nf.fifo,
      bin + "/reflex_inspect " + nf.fifo,
      bin + "/reflex_inspect " + urdf + " --csv " + nf.fifo,
      bin + "/reflex_sim --postures-from " + nf.fifo + " --out " + nf.dir + "/out",
      bin + "/reflex_controller --urdf " + nf.fifo + " --duration 1",
      bin + "/reflex_controller --controller " + nf.fifo + " --duration 1",
      bin + "/reflex_behavior --config " + nf.fifo + " --duration 1",
  };
  for (const std::string& cmd : commands) {
    const auto t0 = std::chrono::steady_clock::now();
    const auto [status, err] = runTool(cmd);
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    EXPECT_NE(status, 0) << cmd;
    EXPECT_NE(status, 137) << cmd << ": killed after 5 s (blocked)";
    EXPECT_LT(s, 4.0) << cmd;
    EXPECT_NE(err.find(nf.fifo), std::string::npos) << cmd << ": " << err;
    EXPECT_NE(err.find("is a FIFO"), std::string::npos) << cmd << ": " << err;
  }
}

}  // namespace
