// The collision meshes of a URDF as the tests read them, independently of the library: tinyxml2 for
// the URDF's collision origins, scales and filenames (package://NAME/ resolved from a map given by the
// test), assimp directly for the files (COLLADA's up axis ignored, as ROS tools and the library do),
// the transforms applied here. Boxes become their 8 corners and 12 triangles. Used as the input of
// the tests' independent answers (FCL's BVH distance between the original meshes).
#pragma once

#include <assimp/Importer.hpp>
#include <assimp/config.h>
#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <gtest/gtest.h>
#include <tinyxml2.h>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <array>
#include <filesystem>
#include <map>
#include <sstream>
#include <string>
#include <vector>

namespace reflex::control::test {

/// Vertices and triangles of a mesh in one frame.
struct RawMesh {
  std::vector<Eigen::Vector3d> v;
  std::vector<std::array<int, 3>> t;
};

inline RawMesh readWithAssimp(const std::string& path, const Eigen::Vector3d& scale, const Eigen::Isometry3d& X) {
  Assimp::Importer importer;
  importer.SetPropertyBool(AI_CONFIG_IMPORT_COLLADA_IGNORE_UP_DIRECTION, true);
  const aiScene* scene = importer.ReadFile(path, aiProcess_Triangulate | aiProcess_PreTransformVertices);
  EXPECT_NE(scene, nullptr) << path << ": " << importer.GetErrorString();
  RawMesh out;
  if (!scene) return out;
  for (unsigned m = 0; m < scene->mNumMeshes; ++m) {
    const aiMesh* am = scene->mMeshes[m];
    const int base = static_cast<int>(out.v.size());
    for (unsigned i = 0; i < am->mNumVertices; ++i)
      out.v.push_back(X * Eigen::Vector3d(scale.x() * am->mVertices[i].x, scale.y() * am->mVertices[i].y,
                                          scale.z() * am->mVertices[i].z));
    for (unsigned f = 0; f < am->mNumFaces; ++f)
      if (am->mFaces[f].mNumIndices == 3)
        out.t.push_back({base + int(am->mFaces[f].mIndices[0]), base + int(am->mFaces[f].mIndices[1]),
                         base + int(am->mFaces[f].mIndices[2])});
  }
  return out;
}

inline Eigen::Vector3d parse3(const char* text, const Eigen::Vector3d& fallback) {
  if (!text) return fallback;
  std::istringstream is(text);
  Eigen::Vector3d v;
  is >> v.x() >> v.y() >> v.z();
  return is ? v : fallback;
}

/// Every link's mesh and box collision geometry in the link frame. `packages`: NAME -> folder for
/// package://NAME/... filenames; other filenames are relative to the URDF's folder.
inline std::map<std::string, RawMesh> linkMeshes(const std::string& urdf_path,
                                                 const std::map<std::string, std::string>& packages) {
  namespace fs = std::filesystem;
  tinyxml2::XMLDocument doc;
  EXPECT_EQ(doc.LoadFile(urdf_path.c_str()), tinyxml2::XML_SUCCESS) << urdf_path;
  std::map<std::string, RawMesh> out;
  if (!doc.RootElement()) return out;
  for (auto* link = doc.RootElement()->FirstChildElement("link"); link; link = link->NextSiblingElement("link")) {
    for (auto* c = link->FirstChildElement("collision"); c; c = c->NextSiblingElement("collision")) {
      Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
      if (auto* o = c->FirstChildElement("origin")) {
        X.translation() = parse3(o->Attribute("xyz"), Eigen::Vector3d::Zero());
        const Eigen::Vector3d rpy = parse3(o->Attribute("rpy"), Eigen::Vector3d::Zero());
        X.linear() = (Eigen::AngleAxisd(rpy.z(), Eigen::Vector3d::UnitZ()) *
                      Eigen::AngleAxisd(rpy.y(), Eigen::Vector3d::UnitY()) *
                      Eigen::AngleAxisd(rpy.x(), Eigen::Vector3d::UnitX()))
                         .toRotationMatrix();
      }
      auto* g = c->FirstChildElement("geometry");
      if (!g) continue;
      RawMesh part;
      if (auto* m = g->FirstChildElement("mesh")) {
        std::string f = m->Attribute("filename") ? m->Attribute("filename") : "";
        bool resolved = false;
        for (const auto& [name, dir] : packages) {
          const std::string pkg = "package://" + name + "/";
          if (f.compare(0, pkg.size(), pkg) == 0) {
            f = dir + "/" + f.substr(pkg.size());
            resolved = true;
          }
        }
        if (!resolved && f.compare(0, 7, "file://") == 0)
          f = f.substr(7);
        else if (!resolved && !f.empty() && f[0] != '/')
          f = fs::path(urdf_path).parent_path().string() + "/" + f;
        part = readWithAssimp(f, parse3(m->Attribute("scale"), Eigen::Vector3d::Ones()), X);
      } else if (auto* b = g->FirstChildElement("box")) {
        const Eigen::Vector3d s = parse3(b->Attribute("size"), Eigen::Vector3d::Zero());
        for (int i = 0; i < 8; ++i)
          part.v.push_back(X * Eigen::Vector3d((i & 1 ? 0.5 : -0.5) * s.x(), (i & 2 ? 0.5 : -0.5) * s.y(),
                                               (i & 4 ? 0.5 : -0.5) * s.z()));
        part.t = {{0, 2, 1}, {1, 2, 3}, {4, 5, 6}, {5, 7, 6}, {0, 1, 4}, {1, 5, 4},
                  {2, 6, 3}, {3, 6, 7}, {0, 4, 2}, {2, 4, 6}, {1, 3, 5}, {3, 7, 5}};
      } else {
        continue;
      }
      RawMesh& all = out[link->Attribute("name")];
      const int base = static_cast<int>(all.v.size());
      all.v.insert(all.v.end(), part.v.begin(), part.v.end());
      for (const auto& t : part.t) all.t.push_back({base + t[0], base + t[1], base + t[2]});
    }
  }
  return out;
}

/// The folder of the shared public robot descriptions (example-robot-data: Romeo, iCub, PR2):
/// $REFLEX_SHARED_ROBOTS, else ../shared/robots beside the checkout, else /work/shared/robots; ""
/// when none exists (the caller fails, naming the places tried).
inline std::string sharedRobotsDir(const std::string& source_dir) {
  namespace fs = std::filesystem;
  std::vector<std::string> tried;
  if (const char* env = std::getenv("REFLEX_SHARED_ROBOTS")) tried.push_back(env);
  tried.push_back(source_dir + "/../shared/robots");
  tried.push_back("/work/shared/robots");
  for (const auto& d : tried)
    if (fs::is_directory(d + "/example-robot-data/robots")) return fs::weakly_canonical(d).string();
  return "";
}

}  // namespace reflex::control::test
