#include "reflex/vision/object_map.hpp"

#include "reflex/vision/output_file.hpp"
#include "yaml_util.hpp"

#include <fstream>
#include <set>
#include <sstream>

namespace reflex::vision {
using namespace detail;

ObjectMap::ObjectMap(std::string family, std::vector<ObjectSpec> objects, const std::string& source)
    : family_(std::move(family)), objects_(std::move(objects)) {
  if (family_.empty()) throw VisionError(source + ": family must not be empty");
  std::set<int> ids;
  std::set<std::string> names;
  for (const ObjectSpec& o : objects_) {
    const std::string where = source + ": object id " + std::to_string(o.tag_id);
    if (o.tag_id < 0) throw VisionError(where + ": tag id must be >= 0");
    if (o.name.empty()) throw VisionError(where + ": empty name");
    if (!(o.tag_size >= kMinTagSize && o.tag_size <= kMaxTagSize))
      throw VisionError(where + ": size = " + fmt(o.tag_size) + " m must be in [" + fmt(kMinTagSize) + ", " +
                        fmt(kMaxTagSize) + "] m (edge of the black square)");
    if (!ids.insert(o.tag_id).second) throw VisionError(where + ": duplicate tag id");
    if (!names.insert(o.name).second) throw VisionError(where + ": duplicate object name '" + o.name + "'");
  }
}

const ObjectSpec* ObjectMap::find(int tag_id) const {
  for (const ObjectSpec& o : objects_)
    if (o.tag_id == tag_id) return &o;
  return nullptr;
}

const ObjectSpec* ObjectMap::findByName(const std::string& name) const {
  for (const ObjectSpec& o : objects_)
    if (o.name == name) return &o;
  return nullptr;
}

ObjectMap parseObjectMap(const std::string& yaml_text, const std::string& source) {
  const YAML::Node root = parseYaml(yaml_text, source);
  std::string family = "tag36h11";
  if (root["family"]) family = asString(root["family"], source + ": family");
  const YAML::Node list = require(root, "objects", source);
  if (!list.IsSequence()) throw VisionError(source + ": objects: expected a list");
  if (list.size() == 0) throw VisionError(source + ": objects: the list is empty (no tag would ever be reported)");
  std::vector<ObjectSpec> objects;
  for (std::size_t i = 0; i < list.size(); ++i) {
    const std::string where = source + ": objects[" + std::to_string(i) + "]";
    ObjectSpec o;
    o.tag_id = asInt(require(list[i], "id", where), where + ".id");
    o.name = asString(require(list[i], "name", where), where + ".name");
    o.tag_size = asDouble(require(list[i], "size", where), where + ".size");
    objects.push_back(o);
  }
  return ObjectMap(family, objects, source);
}

ObjectMap loadObjectMap(const std::string& path) {
  return parseObjectMap(readTextFile(path, "object map"), path);
}

void saveObjectMap(const std::string& path, const ObjectMap& map) {
  std::ostringstream os;
  os << "# Tag id -> object name; size = edge of the tag's black square in metres.\n";
  os << "family: " << map.family() << "\nobjects:\n";
  for (const ObjectSpec& o : map.objects())
    os << "  - {id: " << o.tag_id << ", name: " << o.name << ", size: " << fmt(o.tag_size) << "}\n";
  writeTextFile(path, os.str(), "object map");
}

}  // namespace reflex::vision
