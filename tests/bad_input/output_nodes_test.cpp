// Every file a Reflex tool writes, pointed at something that is not a regular file: a character device
// node of the test's own (1, 3: the kernel's "null"), a FIFO, a directory and a symbolic link to that
// device, each in a private folder. The rule (idl/README.md, "Files a tool writes"):
//   - a file read back as a whole (an overlay, a configuration, a calibration, an image, a scene module,
//     the robot-state file) and every output folder: anything but a regular file (a folder) is refused
//     before any work, exit non-zero, the message naming the path and what it is;
//   - a stream (the controller's --log, reflex_vision --dump, a recording, a CSV export) is written
//     through: a device or a FIFO a reader holds open receives it, a directory is refused.
// After every case each node is still what it was and nothing else is left in the folder. The
// independent answer is lstat(2) on the nodes and the exit status and stderr of the real executables.
// Needs root (mknod), as the suite runs. reflex_record record uses DDS domain 198.
#include "support/child_process.hpp"

#include <gtest/gtest.h>

#include <sys/stat.h>
#include <sys/sysmacros.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <set>
#include <string>
#include <vector>

namespace {

namespace fs = std::filesystem;
using reflex::testing::ProcessResult;
using reflex::testing::runShell;

std::string kindOf(const std::string& p) {
  struct stat st {};
  if (::lstat(p.c_str(), &st) != 0) return "missing";
  if (S_ISCHR(st.st_mode)) return "chr";
  if (S_ISFIFO(st.st_mode)) return "fifo";
  if (S_ISDIR(st.st_mode)) return "dir";
  if (S_ISLNK(st.st_mode)) return "link";
  if (S_ISREG(st.st_mode)) return "reg";
  return "other";
}

std::set<std::string> entries(const std::string& dir) {
  std::set<std::string> names;
  for (const auto& e : fs::directory_iterator(dir)) names.insert(e.path().filename().string());
  return names;
}

/// The private folder: `nodes/` holds the four nodes; `in/` the inputs the tools read.
struct Nodes {
  std::string root, nodes, in, dev, fifo, dir, link;
  Nodes() {
    std::string templ = ::testing::TempDir() + "reflex_output_nodes_XXXXXX";
    if (!mkdtemp(templ.data())) throw std::runtime_error("mkdtemp failed");
    root = templ;
    nodes = root + "/nodes";
    in = root + "/in";
    fs::create_directories(nodes);
    fs::create_directories(in);
    dev = nodes + "/null_device";
    fifo = nodes + "/fifo";
    dir = nodes + "/folder";
    link = nodes + "/link_to_device";
    if (::mknod(dev.c_str(), S_IFCHR | 0666, makedev(1, 3)) != 0)
      throw std::runtime_error(std::string("mknod needs root: ") + std::strerror(errno));
    if (::mkfifo(fifo.c_str(), 0600) != 0) throw std::runtime_error("mkfifo failed");
    fs::create_directories(dir);
    fs::create_symlink(dev, link);
  }
  ~Nodes() {
    std::error_code ec;
    fs::remove_all(root, ec);
  }
  void expectIntact(const std::string& what) const {
    EXPECT_EQ(kindOf(dev), "chr") << what;
    EXPECT_EQ(kindOf(fifo), "fifo") << what;
    EXPECT_EQ(kindOf(dir), "dir") << what;
    EXPECT_EQ(kindOf(link), "link") << what;
    EXPECT_EQ(entries(nodes), (std::set<std::string>{"null_device", "fifo", "folder", "link_to_device"})) << what;
    EXPECT_TRUE(fs::is_empty(dir)) << what << ": wrote into the folder given as a file";
  }
};

enum class Kind {
  kWhole,         ///< a file read back as a whole: every non-regular node refused
  kFolder,        ///< an output folder: device, FIFO and link to a device refused (a folder is what it wants)
  kStream,        ///< written through a device or a FIFO; a folder refused
  kFileOrFolder,  ///< a file (as kWhole) or an existing folder to write into (reflex_detect --draw)
};

struct Tool {
  std::string name;
  std::string command;  ///< "{OUT}" is replaced by the node's path
  Kind kind;
};

std::string replaced(std::string s, const std::string& out) {
  for (std::size_t at; (at = s.find("{OUT}")) != std::string::npos;) s.replace(at, 5, out);
  return s;
}

const char* phrase(const std::string& node_kind) {
  if (node_kind == "chr") return "is a character device";
  if (node_kind == "fifo") return "is a FIFO (named pipe)";
  return "is a directory";
}

TEST(OutputNodes, EveryWritingToolRefusesOrWritesThroughAndLeavesEveryNodeAsItWas) {
  const Nodes n;
  const std::string bin = REFLEX_BIN_DIR, src = REFLEX_SOURCE_DIR;
  const std::string asimo = src + "/bringup/robots/asimo_like.urdf";
  const std::string mesh = src + "/bringup/robots/mesh_humanoid.urdf --package-path mesh_humanoid_description=" + src +
                           "/bringup/robots/mesh_humanoid_description";
  const std::string seed = src + "/tests/fuzz/seeds/recording.rfx";
  const std::string session = src + "/bringup/sessions/flagship";
  // Inputs made by the tools themselves (regular files in in/).
  const std::string board = n.in + "/board.png", log = n.in + "/log.csv", observations = n.in + "/observations.csv",
                    opencv = n.in + "/stereo.yml";
  {
    const ProcessResult b = runShell(bin + "/reflex_calibrate board --out " + board + " 2>&1");
    ASSERT_EQ(b.exit_code, 0) << b.out;
    const ProcessResult l =
        runShell(bin + "/reflex_controller --urdf " + asimo + " --duration 0.2 --log " + log + " --domain 198 2>&1");
    ASSERT_EQ(l.exit_code, 0) << l.out;
    std::ofstream(observations) << "view,x_cam,y_cam,z_cam\n";
    std::ofstream(opencv) << "%YAML:1.0\n";
  }
  const std::vector<Tool> tools = {
      {"reflex_fit -o", bin + "/reflex_fit " + mesh + " -o {OUT}", Kind::kWhole},
      {"reflex_inspect --write", bin + "/reflex_inspect " + asimo + " --sample-pairs 100 --write {OUT} --force",
       Kind::kWhole},
      {"reflex_controller --robot-state",
       bin + "/reflex_controller --urdf " + asimo + " --duration 0.2 --domain 198 --robot-state {OUT}", Kind::kWhole},
      {"reflex_calibrate board --out", bin + "/reflex_calibrate board --out {OUT}", Kind::kWhole},
      {"reflex_calibrate mount --out",
       bin + "/reflex_calibrate mount --urdf " + asimo + " --hand-link l_hand --tag-point 0,0,0 --observations " +
           observations + " --out {OUT}",
       Kind::kWhole},
      {"reflex_detect --draw", bin + "/reflex_detect " + board + " --draw {OUT}", Kind::kFileOrFolder},
      {"reflex_scene --out", bin + "/reflex_scene --log " + log + " --at 0.1 --out {OUT}", Kind::kWhole},
      {"reflex_setup --out", bin + "/reflex_setup " + mesh + " --out {OUT}", Kind::kFolder},
      {"reflex_sim --out", bin + "/reflex_sim target_inside_body --no-plots --out {OUT}", Kind::kFolder},
      {"reflex_record export --dir", bin + "/reflex_record export " + seed + " --dir {OUT}", Kind::kFolder},
      {"reflex_calibrate calibrate --out", bin + "/reflex_calibrate calibrate --session " + session + " --out {OUT}",
       Kind::kFolder},
      {"reflex_calibrate convert --out", bin + "/reflex_calibrate convert " + opencv + " --out {OUT}", Kind::kFolder},
      {"reflex_make_session --out",
       bin + "/reflex_make_session --script " + session + "/scene.yaml --quiet --out {OUT}", Kind::kFolder},
      {"reflex_vision_record --out",
       bin + "/reflex_vision_record --from-files " + session + "/left.mp4 " + session + "/right.mp4 --calib-left " +
           session + "/left.yaml --calib-right " + session + "/right.yaml --objects " + session +
           "/objects.yaml --quiet --out {OUT}",
       Kind::kFolder},
      {"reflex_controller --log",
       bin + "/reflex_controller --urdf " + asimo + " --duration 0.2 --domain 198 --log {OUT}", Kind::kStream},
      {"reflex_vision --dump", bin + "/reflex_vision --session " + session + " --duration 1 --dump {OUT}",
       Kind::kStream},
      {"reflex_record export --csv", bin + "/reflex_record export " + seed + " --topic reflex/joint_state --csv {OUT}",
       Kind::kStream},
      {"reflex_record convert", bin + "/reflex_record convert " + seed + " {OUT} --format mcap", Kind::kStream},
      {"reflex_record record -o", bin + "/reflex_record record --domain 198 --duration 1 -o {OUT}", Kind::kStream},
  };
  struct Node {
    std::string path, kind;  ///< kind: what the path resolves to
  };
  const std::vector<Node> nodes = {{n.dev, "chr"}, {n.fifo, "fifo"}, {n.dir, "dir"}, {n.link, "chr"}};
  for (const Tool& t : tools) {
    for (const Node& node : nodes) {
      // A folder is what it wants.
      if ((t.kind == Kind::kFolder || t.kind == Kind::kFileOrFolder) && node.kind == "dir") continue;
      const std::string what = t.name + " " + node.path;
      const std::string cmd = replaced(t.command, node.path);
      const bool through = t.kind == Kind::kStream && node.kind != "dir";
      // A FIFO written through needs a reader; one that is never opened for writing is let go at 30 s.
      const std::string reader =
          through && node.kind == "fifo" ? "timeout 30 cat " + node.path + " > /dev/null & " : std::string();
      const ProcessResult r = runShell(reader + "timeout -s KILL 120 " + cmd + " > /dev/null 2> " + n.root +
                                       "/err.txt; rc=$?; wait; exit $rc");
      std::ifstream err_in(n.root + "/err.txt");
      const std::string err((std::istreambuf_iterator<char>(err_in)), std::istreambuf_iterator<char>());
      std::printf("%-34s %-15s exit %3d  %s\n", t.name.c_str(), fs::path(node.path).filename().c_str(), r.exit_code,
                  err.substr(0, err.find('\n')).substr(0, 160).c_str());
      if (through) {
        EXPECT_EQ(r.exit_code, 0) << what << " is written through\n" << err;
      } else {
        EXPECT_TRUE(r.exit_code != 0 && r.exit_code != -1 && r.exit_code != 137)
            << what << ": exit " << r.exit_code << "\n"
            << err;
        EXPECT_NE(err.find("'" + node.path + "'"), std::string::npos) << what << ": the path is not named\n" << err;
        EXPECT_NE(err.find(phrase(node.kind)), std::string::npos) << what << ": the kind is not named\n" << err;
      }
      n.expectIntact(what);
    }
  }
}

}  // namespace
