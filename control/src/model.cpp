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
  return -1;
}

}  // namespace reflex::control
