// Mesh files: URDF filename resolution, reading with assimp, and the hash of a link's fit inputs.
#include "fit_inputs.hpp"
#include "reflex/control/urdf_loader.hpp"

#include <assimp/Importer.hpp>
#include <assimp/config.h>
#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <tinyxml2.h>
#include <urdf_model/model.h>

#include <algorithm>
#include <cmath>
#include <array>
#include <cinttypes>
#include <map>
#include <cstdio>
#include <cstdlib>
#include <dirent.h>
#include <fstream>
#include <sstream>
#include <sys/stat.h>

namespace reflex::control {
namespace {

bool isDirectory(const std::string& path) {
  struct stat st {};
  return ::stat(path.c_str(), &st) == 0 && S_ISDIR(st.st_mode);
}

/// The <name> of a package.xml, "" if none or unreadable.
std::string packageXmlName(const std::string& dir) {
  tinyxml2::XMLDocument doc;
  if (doc.LoadFile((dir + "/package.xml").c_str()) != tinyxml2::XML_SUCCESS) return "";
  const tinyxml2::XMLElement* root = doc.RootElement();
  const tinyxml2::XMLElement* name = root ? root->FirstChildElement("name") : nullptr;
  return name && name->GetText() ? std::string(name->GetText()) : "";
}

bool isPackage(const std::string& dir, const std::string& base_name, const std::string& name) {
  if (!isDirectory(dir)) return false;
  const std::string declared = packageXmlName(dir);
  return declared.empty() ? base_name == name : declared == name;
}

/// ROS_PACKAGE_PATH lookup: each folder itself, then its direct children (sorted, for determinism).
std::string findInRosPackagePath(const std::string& name) {
  const char* env = std::getenv("ROS_PACKAGE_PATH");
  if (!env) return "";
  std::stringstream ss(env);
  std::string entry;
  while (std::getline(ss, entry, ':')) {
    if (entry.empty()) continue;
    while (entry.size() > 1 && entry.back() == '/') entry.pop_back();
    const auto slash = entry.rfind('/');
    if (isPackage(entry, slash == std::string::npos ? entry : entry.substr(slash + 1), name)) return entry;
    DIR* d = ::opendir(entry.c_str());
    if (!d) continue;
    std::vector<std::string> children;
    while (const dirent* e = ::readdir(d))
      if (e->d_name[0] != '.') children.emplace_back(e->d_name);
    ::closedir(d);
    std::sort(children.begin(), children.end());
    for (const auto& c : children)
      if (isPackage(entry + "/" + c, c, name)) return entry + "/" + c;
  }
  return "";
}

std::string fmt17(double v) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.17g", v);
  return buf;
}

struct Fnv1a {
  std::uint64_t h = 14695981039346656037ULL;
  void add(const void* data, std::size_t n) {
    const auto* p = static_cast<const unsigned char*>(data);
    for (std::size_t i = 0; i < n; ++i) {
      h ^= p[i];
      h *= 1099511628211ULL;
    }
  }
  void add(const std::string& s) { add(s.data(), s.size() + 1); }  // with the terminator: "ab","c" != "a","bc"
};

}  // namespace

std::string detail::folderOf(const std::string& path) {
  const auto slash = path.rfind('/');
  if (slash == std::string::npos) return ".";
  return slash == 0 ? "/" : path.substr(0, slash);
}

std::string resolveMeshFilename(const std::string& filename, const std::string& urdf_dir, const PackagePaths& paths,
                                std::string* why) {
  const std::string kPackage = "package://";
  const std::string kFile = "file://";
  if (filename.compare(0, kPackage.size(), kPackage) == 0) {
    const std::string rest = filename.substr(kPackage.size());
    const auto slash = rest.find('/');
    const std::string name = rest.substr(0, slash);
    const std::string rel = slash == std::string::npos ? "" : rest.substr(slash + 1);
    if (name.empty() || rel.empty()) {
      if (why) *why = "malformed package URI (expected package://NAME/path)";
      return "";
    }
    std::string dir;
    if (const auto it = paths.packages.find(name); it != paths.packages.end())
      dir = it->second;
    else if (paths.use_ros_package_path)
      dir = findInRosPackagePath(name);
    if (dir.empty()) {
      if (why)
        *why = "package '" + name + "' not found (give --package-path " + name +
               "=DIR, or add its parent folder to ROS_PACKAGE_PATH" +
               (std::getenv("ROS_PACKAGE_PATH") ? std::string(", now '") + std::getenv("ROS_PACKAGE_PATH") + "'"
                                                : std::string(", unset now")) +
               ")";
      return "";
    }
    return dir + "/" + rel;
  }
  if (filename.compare(0, kFile.size(), kFile) == 0) {
    const std::string path = filename.substr(kFile.size());
    if (path.empty() || path[0] != '/') {
      if (why) *why = "a file:// URI must hold an absolute path";
      return "";
    }
    return path;
  }
  if (filename.find("://") != std::string::npos) {
    if (why) *why = "unsupported URI scheme (package://, file:// or a path)";
    return "";
  }
  if (filename.empty()) {
    if (why) *why = "empty filename";
    return "";
  }
  return filename[0] == '/' ? filename : urdf_dir + "/" + filename;
}

namespace {

// The file as read, before any post-processing: at most kMaxMeshTriangles faces (a 1 M-triangle STL
// took 358 s and 8.1 GB to fit; collision meshes are a few thousand), every vertex finite.
void checkRawMesh(const aiScene& scene, const std::string& path) {
  std::size_t faces = 0;
  for (unsigned m = 0; m < scene.mNumMeshes; ++m) faces += scene.mMeshes[m]->mNumFaces;
  if (faces > kMaxMeshTriangles)
    throw ModelError(path + ": mesh has " + std::to_string(faces) + " triangles, more than the " +
                     std::to_string(kMaxMeshTriangles) +
                     " a collision mesh may have: decimate it (a collision "
                     "mesh needs the shape, not the detail)");
  for (unsigned m = 0; m < scene.mNumMeshes; ++m) {
    const aiMesh& am = *scene.mMeshes[m];
    for (unsigned v = 0; v < am.mNumVertices; ++v) {
      const aiVector3D& p = am.mVertices[v];
      if (std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z)) continue;
      char buf[160];
      std::snprintf(buf, sizeof buf, "(%g, %g, %g)", p.x, p.y, p.z);
      throw ModelError(path + ": mesh vertex " + std::to_string(v) + " of mesh " + std::to_string(m) + " at " + buf +
                       " is not finite");
    }
  }
}

}  // namespace

TriangleMesh loadMeshFile(const std::string& path, const Eigen::Vector3d& scale) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) throw ModelError(path + ": mesh file does not exist");
  if (!S_ISREG(st.st_mode)) throw ModelError(path + ": mesh path is not a regular file");
  Assimp::Importer importer;
  // As RViz and MoveIt (geometric_shapes) read meshes: the COLLADA up axis is ignored (the URDF's
  // frame is the mesh's frame), its <unit meter> is applied by assimp. Lines and points are dropped.
  importer.SetPropertyBool(AI_CONFIG_IMPORT_COLLADA_IGNORE_UP_DIRECTION, true);
  importer.SetPropertyInteger(AI_CONFIG_PP_SBP_REMOVE, aiPrimitiveType_LINE | aiPrimitiveType_POINT);
  // Read as the file has it first: its size and every vertex are checked before any post-processing
  // (assimp's vertex joining merged a NaN vertex into another; the scene graph's transforms cannot
  // make a finite vertex of a NaN one, so the raw values are what counts).
  const aiScene* raw = importer.ReadFile(path, 0);
  if (!raw) throw ModelError(path + ": cannot read mesh: " + importer.GetErrorString());
  checkRawMesh(*raw, path);
  const aiScene* scene = importer.ApplyPostProcessing(aiProcess_Triangulate | aiProcess_PreTransformVertices |
                                                      aiProcess_JoinIdenticalVertices | aiProcess_SortByPType);
  if (!scene) throw ModelError(path + ": cannot read mesh: " + importer.GetErrorString());

  // Vertices with the same position are one vertex (an STL repeats them per face; assimp keeps
  // copies that differ only in their normals).
  TriangleMesh mesh;
  std::map<std::array<double, 3>, int> index_of;
  for (unsigned m = 0; m < scene->mNumMeshes; ++m) {
    const aiMesh* am = scene->mMeshes[m];
    std::vector<int> id(am->mNumVertices);
    for (unsigned v = 0; v < am->mNumVertices; ++v) {
      const aiVector3D& p = am->mVertices[v];
      const std::array<double, 3> key{scale.x() * p.x, scale.y() * p.y, scale.z() * p.z};
      // After the scene's transforms and the scale: the range of URDF lengths (a vertex at 1e30 m
      // became a 1e30 m capsule).
      for (const double c : key)
        if (!std::isfinite(c) || std::abs(c) > kMaxMeshCoordinate) {
          char buf[160];
          std::snprintf(buf, sizeof buf, "(%g, %g, %g) m", key[0], key[1], key[2]);
          throw ModelError(
              path + ": mesh vertex " + std::to_string(v) + " of mesh " + std::to_string(m) + " at " + buf +
              (std::isfinite(c) ? " is out of range (|coordinate| <= " +
                                      std::to_string(static_cast<int>(kMaxMeshCoordinate)) + " m after scale)"
                                : " is not finite"));
        }
      const auto [it, inserted] = index_of.emplace(key, static_cast<int>(mesh.vertices.size()));
      if (inserted) mesh.vertices.emplace_back(key[0], key[1], key[2]);
      id[v] = it->second;
    }
    for (unsigned f = 0; f < am->mNumFaces; ++f) {
      const aiFace& face = am->mFaces[f];
      if (face.mNumIndices != 3) continue;
      mesh.triangles.push_back({id[face.mIndices[0]], id[face.mIndices[1]], id[face.mIndices[2]]});
    }
  }
  if (mesh.triangles.empty()) throw ModelError(path + ": mesh has no triangles");
  for (const auto& v : mesh.vertices)
    if (!v.allFinite()) throw ModelError(path + ": mesh has a vertex that is not finite");
  return mesh;
}

std::vector<detail::FitElement> detail::fitElementsOf(const urdf::Link& link) {
  std::vector<urdf::CollisionSharedPtr> collisions = link.collision_array;
  if (collisions.empty() && link.collision) collisions.push_back(link.collision);
  std::vector<FitElement> out;
  for (const auto& c : collisions) {
    if (!c || !c->geometry) continue;
    FitElement e;
    e.name = c->name;
    const urdf::Pose& pose = c->origin;
    e.X_L_C.linear() = Eigen::Quaterniond(pose.rotation.w, pose.rotation.x, pose.rotation.y, pose.rotation.z)
                           .normalized()
                           .toRotationMatrix();
    e.X_L_C.translation() = Eigen::Vector3d(pose.position.x, pose.position.y, pose.position.z);
    if (c->geometry->type == urdf::Geometry::MESH) {
      const auto& mesh = static_cast<const urdf::Mesh&>(*c->geometry);
      e.filename = mesh.filename;
      e.scale = Eigen::Vector3d(mesh.scale.x, mesh.scale.y, mesh.scale.z);
    } else if (c->geometry->type == urdf::Geometry::BOX) {
      const auto& box = static_cast<const urdf::Box&>(*c->geometry);
      e.box = true;
      e.size = Eigen::Vector3d(box.dim.x, box.dim.y, box.dim.z);
    } else {
      continue;
    }
    out.push_back(e);
  }
  return out;
}

std::string detail::fitInputsHash(const std::string& link, const std::vector<FitElement>& elements,
                                  const std::string& urdf_dir, const PackagePaths& paths,
                                  std::vector<std::string>* problems, std::vector<std::string>* resolved) {
  Fnv1a h;
  for (const auto& e : elements) {
    h.add(e.box ? "box" : "mesh");
    h.add(e.filename);
    for (int i = 0; i < 3; ++i) h.add(fmt17(e.box ? e.size[i] : e.scale[i]));
    for (int r = 0; r < 3; ++r) {
      h.add(fmt17(e.X_L_C.translation()[r]));
      for (int c = 0; c < 3; ++c) h.add(fmt17(e.X_L_C.linear()(r, c)));
    }
    if (e.box) continue;
    std::string why;
    const std::string path = resolveMeshFilename(e.filename, urdf_dir, paths, &why);
    if (path.empty()) {
      if (resolved) resolved->push_back("");
      if (problems) problems->push_back("link '" + link + "': mesh '" + e.filename + "': " + why);
      continue;
    }
    struct stat st {};
    const bool exists = ::stat(path.c_str(), &st) == 0;
    std::ifstream in;
    if (exists && S_ISREG(st.st_mode)) in.open(path, std::ios::binary);
    if (!in.is_open()) {  // reported once here; "" tells the caller not to read it again
      if (resolved) resolved->push_back("");
      if (problems)
        problems->push_back("link '" + link + "': mesh '" + e.filename + "': cannot read '" + path + "'" +
                            (!exists                ? " (no such file)"
                             : !S_ISREG(st.st_mode) ? " (not a regular file)"
                                                    : ""));
      continue;
    }
    if (resolved) resolved->push_back(path);
    std::stringstream bytes;
    bytes << in.rdbuf();
    const std::string b = bytes.str();
    h.add(b.data(), b.size());
  }
  char buf[20];
  std::snprintf(buf, sizeof buf, "%016" PRIx64, h.h);
  return buf;
}

}  // namespace reflex::control
