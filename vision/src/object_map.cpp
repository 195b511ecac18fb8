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
  const ConfigNode root = parseYaml(yaml_text, source);
  root.rejectUnknown({"family", "objects"});
  const std::string family = root.string("family", "tag36h11");
  const std::vector<ConfigNode> list = root.at("objects", "a list of {id, name, size}").elements();
  if (list.empty()) root.fail("objects", "the list is empty (no tag would ever be reported)", "at least one object");
  std::vector<ObjectSpec> objects;
  for (const ConfigNode& item : list) {
    item.requireMap("{id, name, size}");
    item.rejectUnknown({"id", "name", "size"});
    ObjectSpec o;
    o.tag_id = item.at("id", "a tag id").asInteger(0, std::numeric_limits<int>::max());
    o.name = item.requiredString("name", "the object's name");
    o.tag_size =
        item.requiredNumber("size", ObjectMap::kMinTagSize, ObjectMap::kMaxTagSize, "m (edge of the black square)");
    objects.push_back(o);
  }
  return ObjectMap(family, objects, source);
}

ObjectMap loadObjectMap(const std::string& path) { return parseObjectMap(readTextFile(path, "object map"), path); }

void saveObjectMap(const std::string& path, const ObjectMap& map) {
  std::ostringstream os;
  os << "# Tag id -> object name; size = edge of the tag's black square in metres.\n";
  os << "family: " << map.family() << "\nobjects:\n";
  for (const ObjectSpec& o : map.objects())
    os << "  - {id: " << o.tag_id << ", name: " << o.name << ", size: " << fmt(o.tag_size) << "}\n";
  writeTextFile(path, os.str(), "object map");
}

}  // namespace reflex::vision
