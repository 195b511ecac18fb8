#pragma once
// Tag id -> object name and tag size. Read from a session's objects.yaml or a config file:
//
//   family: tag36h11            # optional; the AprilTag family the ids belong to
//   objects:
//     - {id: 0, name: cup, size: 0.06}   # size: outer edge of the black border, metres
//
// Invariants: ids >= 0 and unique, names non-empty and unique, sizes in [kMinTagSize, kMaxTagSize];
// a file (parseObjectMap) names at least one object (with none, no tag is ever reported).
#include <optional>
#include <string>
#include <vector>

namespace reflex::vision {

struct ObjectSpec {
  int tag_id = 0;
  std::string name;
  double tag_size = 0.0;  ///< metres, edge of the black square (AprilTag convention)
};

class ObjectMap {
 public:
  /// Tag edge length range, metres: below 2 mm no camera resolves the bits, above 5 m it is a wall.
  static constexpr double kMinTagSize = 0.002;
  static constexpr double kMaxTagSize = 5.0;
  ObjectMap() = default;
  /// Throws VisionError on duplicate ids/names, empty names or sizes outside [kMinTagSize,
  /// kMaxTagSize]; `source` is quoted.
  ObjectMap(std::string family, std::vector<ObjectSpec> objects, const std::string& source);

  const std::string& family() const { return family_; }
  const std::vector<ObjectSpec>& objects() const { return objects_; }
  /// nullptr if the id is not in the map.
  const ObjectSpec* find(int tag_id) const;
  const ObjectSpec* findByName(const std::string& name) const;

 private:
  std::string family_ = "tag36h11";
  std::vector<ObjectSpec> objects_;
};

ObjectMap parseObjectMap(const std::string& yaml_text, const std::string& source);
ObjectMap loadObjectMap(const std::string& path);
void saveObjectMap(const std::string& path, const ObjectMap& map);

}  // namespace reflex::vision
