#include "reflex/control/model.hpp"

namespace reflex::control {

int Model::linkIndex(const std::string& link_name) const {
  for (std::size_t i = 0; i < links.size(); ++i)
    if (links[i].name == link_name) return static_cast<int>(i);
  return -1;
}

int Model::qIndex(const std::string& joint_name) const {
  for (std::size_t i = 0; i < q_names.size(); ++i)
    if (q_names[i] == joint_name) return static_cast<int>(i);
  return -1;
}

int Model::segmentIndex(const std::string& segment_name) const {
  for (std::size_t i = 0; i < segments.size(); ++i)
    if (segments[i].name == segment_name) return static_cast<int>(i);
  const int link = linkIndex(segment_name);
  if (link < 0) return -1;
  for (std::size_t i = 0; i < segments.size(); ++i) {
    const Segment& seg = segments[i];
    if (seg.body_schema_slot) continue;
    for (int p = seg.first_primitive; p < seg.first_primitive + seg.num_primitives; ++p)
      if (primitives[static_cast<std::size_t>(p)].link == link) return static_cast<int>(i);
  }
  return -1;
}

std::string robotFileBeside(const std::string& urdf_path, const std::string& suffix) {
  const auto dot = urdf_path.rfind('.');
  const auto slash = urdf_path.rfind('/');
  const bool has_extension = dot != std::string::npos && (slash == std::string::npos || dot > slash);
  return (has_extension ? urdf_path.substr(0, dot) : urdf_path) + suffix;
}

}  // namespace reflex::control
