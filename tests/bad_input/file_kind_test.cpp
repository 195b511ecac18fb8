// A file argument that is not a regular file -- a FIFO (mkfifo), a character
// device (/dev/zero), a directory -- is refused at once, with an error that names the path and what it
// is, by every loader of a file a user names (and by the tools that take such files). The old loaders
// blocked forever on a FIFO (open(2) waits for a writer) and read /dev/zero without end.
//
// Independent answer: each call runs in a child process with a deadline of one second; the child
// reports whether the loader threw its documented error type with the path and the kind ("is a FIFO
// (named pipe)", "is a character device", "is a directory") in the message. A blocked child is killed
// and the case fails. Tools: the real executables under `timeout`, exit status and stderr checked.
//
// Recorder and tools: output that cannot be written is not success. /dev/full
// (every write fails with ENOSPC) as a recording, a CSV export, a time series (through a symbolic
// link in the output folder) and as standard output; a missing or impossible output folder is an
// error at start, before any work. /dev/null stays a valid output. reflex_record record uses DDS
// domain 205 (it fails before it records anything, but its participant joins first: a domain no other test uses).
#include "reflex/bus/error.hpp"
#include "reflex/common/files.hpp"
#include "reflex/bus/participant.hpp"
#include "reflex/control/controller.hpp"
#include "reflex/control/urdf_loader.hpp"
#include "reflex/modules/config.hpp"
#include "reflex/modules/scripted.hpp"
#include "reflex/record/record_file.hpp"
#include "reflex/record/recorder.hpp"
#include "reflex/vision/calibration.hpp"
#include "reflex/vision/error.hpp"
#include "reflex/vision/object_map.hpp"
#include "reflex/vision/session.hpp"
#include "support/child_process.hpp"

#include <gtest/gtest.h>

#include <sys/stat.h>
#include <sys/sysmacros.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>
#include <vector>

namespace {

namespace fs = std::filesystem;
using reflex::testing::ProcessResult;
using reflex::testing::runInChild;
using reflex::testing::runShell;

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
      loader<reflex::vision::VisionError>("camera mount",
                                          [](const std::string& p) { reflex::vision::loadCameraMount(p); }),
      loader<reflex::vision::VisionError>("object map", [](const std::string& p) { reflex::vision::loadObjectMap(p); }),
      loader<reflex::vision::VisionError>("timestamps CSV",
                                          [](const std::string& p) { reflex::vision::loadTimestamps(p); }),
      loader<reflex::vision::VisionError>("ground truth CSV",
                                          [](const std::string& p) { reflex::vision::loadGroundTruth(p); }),
  };
  for (const Loader& l : loaders) {
    for (const auto& [path, kind] : nf.cases()) {
      const int status = runInChild(std::chrono::seconds(1), [&, p = path, k = kind] { return l.run(p, k); });
      EXPECT_EQ(status, 0) << l.name << " given " << path << " (" << kind
                           << "): " << (status == -1 ? "still blocked after 1 s" : "status " + std::to_string(status));
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
  const int status = runInChild(std::chrono::seconds(1), [&] {
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
  const ProcessResult r = runShell("timeout -s KILL 5 " + cmd + " 2>&1 >/dev/null");
  return {r.exit_code, r.out};
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

// ---------------------------------------------------------------- item 14: outputs
TEST(OutputFiles, TheRecordingWriterAndTheExporterNameTheFileAndTheCause) {
  // A full device of the test's own (support/child_process.hpp), not the machine's.
  const std::string& full = reflex::testing::fullDevice();
  using reflex::record::RecordError;
  auto message = [](const std::function<void()>& fn) -> std::string {
    try {
      fn();
    } catch (const RecordError& e) {
      return e.what();
    }
    return "(no error)";
  };
  // A full device: the file header cannot be written -- at construction, not at the end.
  EXPECT_EQ(message([&] { reflex::record::RecordWriter w(full); }),
            "cannot write recording '" + full + "': No space left on device");
  // A folder that does not exist, and a folder in the file's place.
  const std::string missing = message([] { reflex::record::RecordWriter w("/nonexistent_reflex_dir/run.rfx"); });
  EXPECT_NE(
      missing.find("folder '/nonexistent_reflex_dir' of output file '/nonexistent_reflex_dir/run.rfx' does not exist"),
      std::string::npos)
      << missing;
  const NonFiles nf;
  EXPECT_NE(message([&] { reflex::record::RecordWriter w(nf.folder); }).find("is a directory"), std::string::npos);
  // /dev/null stays a valid output (its fsync fails with EINVAL: nothing to lose there).
  {
    reflex::record::RecordWriter w("/dev/null");
    w.append(reflex::record::RecordEntry{1, 2, "t", "T", {1, 2, 3}});
    EXPECT_NO_THROW(w.close());
  }
  // Export: the CSV's folder is checked before the recording is read (the input does not even exist).
  const std::string early = message([] {
    reflex::record::exportCsv("/nonexistent_input.rfx", "reflex/joint_state", "/nonexistent_reflex_dir/x.csv");
  });
  EXPECT_NE(early.find("/nonexistent_reflex_dir"), std::string::npos) << early;
  EXPECT_NE(early.find("does not exist"), std::string::npos) << early;
  const std::string seed = std::string(REFLEX_SOURCE_DIR) + "/tests/fuzz/seeds/recording.rfx";
  EXPECT_EQ(message([&] { reflex::record::exportCsv(seed, "reflex/joint_state", full); }),
            "cannot write '" + full + "': No space left on device");
}

TEST(OutputFiles, ToolsExitNonZeroNamingTheOutputAndTheCause) {
  const std::string& full = reflex::testing::fullDevice();
  const NonFiles nf;
  const std::string bin = REFLEX_BIN_DIR;
  const std::string urdf = std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/asimo_like.urdf";
  const std::string seed = std::string(REFLEX_SOURCE_DIR) + "/tests/fuzz/seeds/recording.rfx";
  // A time series that cannot be written: its name in the output folder links to a full device.
  const std::string sim_out = nf.dir + "/sim";
  fs::create_directories(sim_out);
  fs::create_symlink(full, sim_out + "/timeseries.csv");
  struct Case {
    std::string cmd, expected;
  };
  const std::vector<Case> cases = {
      {bin + "/reflex_inspect " + urdf + " > " + full, "cannot write the standard output: No space left on device"},
      {bin + "/reflex_record info " + seed + " > " + full, "cannot write the standard output: No space left on device"},
      {bin + "/reflex_record export " + seed + " --topic reflex/joint_state --csv " + full,
       "cannot write '" + full + "': No space left on device"},
      {bin + "/reflex_record export " + seed + " --dir /dev/null/csv", "'/dev/null/csv'"},
      {bin + "/reflex_record record --domain 205 -o " + full + " --duration 1",
       "'" + full + "': No space left on device"},
      {bin + "/reflex_record record --domain 205 -o " + nf.dir + "/no/such/run.rfx --duration 1",
       "'" + nf.dir + "/no/such' of output file"},
      {bin + "/reflex_sim target_inside_body --no-plots --out " + nf.dir + "/sim_stdout > " + full,
       "cannot write the standard output: No space left on device"},
      {bin + "/reflex_sim target_inside_body --no-plots --out " + sim_out + " > /dev/null",
       "cannot write '" + sim_out + "/timeseries.csv': No space left on device"},
      {bin + "/reflex_sim target_inside_body --no-plots --out /dev/null/sim", "output folder '/dev/null/sim'"},
      {bin + "/reflex_sim --postures-from " + seed + " --out /dev/null/sim", "output folder '/dev/null/sim'"},
  };
  for (const Case& c : cases) {
    // stderr only (the commands redirect their own stdout).
    const ProcessResult r = runShell("timeout -s KILL 20 " + c.cmd);
    const std::string& err = r.out;
    EXPECT_TRUE(r.exit_code != -1 && r.exit_code != 0 && r.exit_code != 137) << c.cmd << "\n" << err;
    EXPECT_NE(err.find(c.expected), std::string::npos) << c.cmd << "\n" << err;
  }
}

// The atomic replace behind reflex_fit -o, reflex_setup and reflex_inspect --write (writeFileReplacing)
// never replaces a node that is not a regular file. In a private folder: a character device of our own
// (1, 7: the kernel's "full"), a FIFO, a directory and a link to that device are refused naming the
// path and the kind, and each is still what it was; a link to a regular file is written through (the
// target replaced, the link kept); no temporary file is left. Then reflex_fit -o that device, the
// case that turned /dev/full into a regular file. Needs root (mknod), as the suite runs.
TEST(OutputFiles, AnAtomicReplaceNeverReplacesADeviceAFifoOrAFolder) {
  const NonFiles nf;
  const std::string dev = nf.dir + "/full";
  ASSERT_EQ(::mknod(dev.c_str(), S_IFCHR | 0666, makedev(1, 7)), 0) << "mknod needs root: " << std::strerror(errno);
  const std::string link_dev = nf.dir + "/link_to_full", regular = nf.dir + "/regular.yaml",
                    link_reg = nf.dir + "/link_to_regular.yaml";
  fs::create_symlink(dev, link_dev);
  { std::ofstream(regular) << "old\n"; }
  fs::create_symlink(regular, link_reg);
  auto kind = [](const std::string& p) {
    struct stat st {};
    if (::lstat(p.c_str(), &st) != 0) return std::string("missing");
    return std::string(S_ISCHR(st.st_mode)    ? "chr"
                       : S_ISFIFO(st.st_mode) ? "fifo"
                       : S_ISDIR(st.st_mode)  ? "dir"
                       : S_ISLNK(st.st_mode)  ? "link"
                       : S_ISREG(st.st_mode)  ? "reg"
                                              : "other");
  };
  const std::vector<std::pair<std::string, std::string>> refused = {
      {dev, "is a character device"},
      {nf.fifo, "is a FIFO (named pipe)"},
      {nf.folder, "is a directory"},
      {link_dev, "(a link to '" + dev + "') is a character device"}};
  for (const auto& [path, what] : refused) {
    const std::string before = kind(path);
    const std::string why = reflex::common::writeFileReplacing(path, "text\n");
    EXPECT_NE(why.find("output file '" + path + "'"), std::string::npos) << why;
    EXPECT_NE(why.find(what + ": only a regular file is ever replaced"), std::string::npos) << why;
    EXPECT_EQ(kind(path), before) << path;
  }
  EXPECT_EQ(kind(dev), "chr");
  EXPECT_EQ(reflex::common::writeFileReplacing(link_reg, "new\n"), "");
  EXPECT_EQ(kind(link_reg), "link");
  std::ifstream in(regular);
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_EQ(text, "new\n");
  for (const auto& e : fs::directory_iterator(nf.dir))
    EXPECT_EQ(e.path().string().find(".tmp"), std::string::npos) << "left behind: " << e.path();

  const std::string mesh_urdf = std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/mesh_humanoid.urdf";
  const std::string pkg = std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/mesh_humanoid_description";
  const ProcessResult r = runShell("timeout -s KILL 120 " + std::string(REFLEX_BIN_DIR) + "/reflex_fit " + mesh_urdf +
                                   " --package-path mesh_humanoid_description=" + pkg + " -o " + dev + " 2>&1");
  EXPECT_TRUE(r.exit_code != 0 && r.exit_code != -1) << r.out;
  EXPECT_NE(r.out.find("output file '" + dev + "' is a character device"), std::string::npos) << r.out;
  EXPECT_EQ(kind(dev), "chr") << "reflex_fit replaced the device node";

  // reflex_inspect --sample-pairs --write: the same rule, before the sampling.
  const ProcessResult ri = runShell("timeout -s KILL 60 " + std::string(REFLEX_BIN_DIR) + "/reflex_inspect " +
                                    std::string(REFLEX_SOURCE_DIR) +
                                    "/bringup/robots/asimo_like.urdf --sample-pairs 100 "
                                    "--write " +
                                    link_dev + " --force 2>&1");
  EXPECT_TRUE(ri.exit_code != 0 && ri.exit_code != -1) << ri.out;
  EXPECT_NE(ri.out.find("--write: output file '" + link_dev + "' (a link to '" + dev + "') is a character device"),
            std::string::npos)
      << ri.out;
  EXPECT_EQ(kind(dev), "chr");
  EXPECT_EQ(kind(link_dev), "link");
}

}  // namespace
