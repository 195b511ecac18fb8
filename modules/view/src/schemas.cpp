// JSON schemas of the scene channels (scene.hpp). Written from the published foxglove schema
// definitions (https://docs.foxglove.dev/docs/visualization/message-schemas: field names, types and
// enum values); built here from small helpers rather than kept as long literal text.
#include "reflex/view/scene.hpp"

#include <utility>

namespace reflex::view {
namespace {

using nlohmann::json;

json typed(const char* type, const char* description) { return json{{"type", type}, {"description", description}}; }
json number(const char* d) { return typed("number", d); }
json string(const char* d) { return typed("string", d); }
json boolean(const char* d) { return typed("boolean", d); }
json integer(const char* d) { return typed("integer", d); }

/// An object whose every property is required (as in foxglove's published schemas).
json object(const char* title, const char* description, json properties) {
  json required = json::array();
  for (const auto& item : properties.items()) required.push_back(item.key());
  return json{{"title", title},
              {"description", description},
              {"type", "object"},
              {"properties", std::move(properties)},
              {"required", std::move(required)}};
}
json array(json items, const char* description) {
  return json{{"type", "array"}, {"items", std::move(items)}, {"description", description}};
}

json time(const char* description) {
  return json{{"type", "object"},
              {"title", "time"},
              {"description", description},
              {"properties",
               {{"sec", {{"type", "integer"}, {"minimum", 0}}},
                {"nsec", {{"type", "integer"}, {"minimum", 0}, {"maximum", 999999999}}}}}};
}
json duration(const char* description) {
  return json{
      {"type", "object"},
      {"title", "duration"},
      {"description", description},
      {"properties",
       {{"sec", {{"type", "integer"}}}, {"nsec", {{"type", "integer"}, {"minimum", 0}, {"maximum", 999999999}}}}}};
}
json vector3(const char* description) {
  return object("foxglove.Vector3", description,
                {{"x", number("x coordinate length")},
                 {"y", number("y coordinate length")},
                 {"z", number("z coordinate length")}});
}
json point3(const char* description) {
  return object("foxglove.Point3", description,
                {{"x", number("x coordinate position")},
                 {"y", number("y coordinate position")},
                 {"z", number("z coordinate position")}});
}
json quaternion(const char* description) {
  return object(
      "foxglove.Quaternion", description,
      {{"x", number("x value")}, {"y", number("y value")}, {"z", number("z value")}, {"w", number("w value")}});
}
json pose(const char* description) {
  return object("foxglove.Pose", description,
                {{"position", vector3("Point denoting position in 3D space")},
                 {"orientation", quaternion("Quaternion denoting orientation in 3D space")}});
}
json colour(const char* description) {
  return object("foxglove.Color", description,
                {{"r", number("Red value between 0 and 1")},
                 {"g", number("Green value between 0 and 1")},
                 {"b", number("Blue value between 0 and 1")},
                 {"a", number("Alpha value between 0 and 1")}});
}

json sphere() {
  return object("foxglove.SpherePrimitive", "A primitive representing a sphere or ellipsoid",
                {{"pose", pose("Position of the center of the sphere and orientation of the sphere")},
                 {"size", vector3("Size (diameter) of the sphere along each axis")},
                 {"color", colour("Color of the sphere")}});
}
json cylinder() {
  return object(
      "foxglove.CylinderPrimitive", "A primitive representing a cylinder, elliptic cylinder, or truncated cone",
      {{"pose", pose("Position of the center of the cylinder and orientation of the cylinder. The flat face(s) "
                     "are perpendicular to the z-axis.")},
       {"size", vector3("Size of the cylinder's bounding box")},
       {"bottom_scale",
        number("0-1, ratio of the diameter of the cylinder's bottom face (min z) to the bottom of the bounding box")},
       {"top_scale",
        number("0-1, ratio of the diameter of the cylinder's top face (max z) to the top of the bounding box")},
       {"color", colour("Color of the cylinder")}});
}
/// `indices` of the line and triangle primitives (the same field in both published schemas).
json pointIndices() {
  return array(json{{"type", "integer"}, {"minimum", 0}},
               "Indices into the `points` and `colors` attribute arrays, which can be used to avoid duplicating "
               "attribute data.");
}

json line() {
  json type{
      {"title", "foxglove.LineType"},
      {"description", "Drawing primitive to use for lines"},
      {"oneOf",
       json::array(
           {{{"title", "LINE_STRIP"}, {"const", 0}, {"description", "Connected line segments: 0-1, 1-2, ..., (n-1)-n"}},
            {{"title", "LINE_LOOP"}, {"const", 1}, {"description", "Closed polygon: 0-1, 1-2, ..., (n-1)-n, n-0"}},
            {{"title", "LINE_LIST"}, {"const", 2}, {"description", "Individual line segments: 0-1, 2-3, 4-5, ..."}}})}};
  return object(
      "foxglove.LinePrimitive", "A primitive representing a series of points connected by lines",
      {{"type", std::move(type)},
       {"pose", pose("Origin of lines relative to reference frame")},
       {"thickness", number("Line thickness")},
       {"scale_invariant", boolean("Indicates whether `thickness` is a fixed size in screen pixels (true), or "
                                   "specified in world coordinates and scales with distance from the camera (false)")},
       {"points", array(point3("Point in 3D space"), "Points along the line")},
       {"color", colour("Solid color to use for the whole line. One of `color` or `colors` must be provided.")},
       {"colors", array(colour("A color in RGBA format"),
                        "Per-point colors (if specified, must have the same length as `points`).")},
       {"indices", pointIndices()}});
}
json arrow() {
  return object("foxglove.ArrowPrimitive", "A primitive representing an arrow",
                {{"pose", pose("Position of the arrow's tail and orientation of the arrow. Identity orientation means "
                               "the arrow points in the +x direction.")},
                 {"shaft_length", number("Length of the arrow shaft")},
                 {"shaft_diameter", number("Diameter of the arrow shaft")},
                 {"head_length", number("Length of the arrow head")},
                 {"head_diameter", number("Diameter of the arrow head")},
                 {"color", colour("Color of the arrow")}});
}
json cube() {
  return object("foxglove.CubePrimitive", "A primitive representing a cube or rectangular prism",
                {{"pose", pose("Position of the center of the cube and orientation of the cube")},
                 {"size", vector3("Size of the cube along each axis")},
                 {"color", colour("Color of the cube")}});
}
json triangles() {
  return object(
      "foxglove.TriangleListPrimitive", "A primitive representing a set of triangles or a surface tiled by triangles",
      {{"pose", pose("Origin of triangles relative to reference frame")},
       {"points", array(point3("Point in 3D space"),
                        "Vertices to use for triangles, interpreted as a list of triples (0-1-2, 3-4-5, ...)")},
       {"color", colour("Solid color to use for the whole shape. One of `color` or `colors` must be provided.")},
       {"colors", array(colour("A color in RGBA format"),
                        "Per-vertex colors (if specified, must have the same length as `points`).")},
       {"indices", pointIndices()}});
}
json model() {
  return object(
      "foxglove.ModelPrimitive",
      "A primitive representing a 3D model file loaded from an external URL or embedded data",
      {{"pose", pose("Origin of model relative to reference frame")},
       {"scale", vector3("Scale factor to apply to the model along each axis")},
       {"color", colour("Solid color to use for the whole model if `override_color` is true.")},
       {"override_color",
        boolean(
            "Whether to use the color specified in `color` instead of any materials embedded in the original model.")},
       {"url", string("URL pointing to model file. One of `url` or `data` should be provided.")},
       {"media_type",
        string("[Media type](https://developer.mozilla.org/en-US/docs/Web/HTTP/Basics_of_HTTP/MIME_types) of embedded "
               "model (e.g. `model/gltf-binary`). Required if `data` is provided instead of `url`. Overrides the "
               "inferred media type if `url` is provided.")},
       {"data", json{{"type", "string"},
                     {"contentEncoding", "base64"},
                     {"description",
                      "Embedded model. One of `url` or `data` should be provided. If `data` is provided, `media_type` "
                      "must be set to indicate the type of the data."}}}});
}
json text() {
  return object(
      "foxglove.TextPrimitive", "A primitive representing a text label",
      {{"pose", pose("Position of the center of the text box and orientation of the text. Identity orientation means "
                     "the text is oriented in the xy-plane and flows from -x to +x.")},
       {"billboard",
        boolean("Whether the text should respect `pose.orientation` (false) or always face the camera (true)")},
       {"font_size", number("Font size (height of one line of text)")},
       {"scale_invariant", boolean("Indicates whether `font_size` is a fixed size in screen pixels (true), or "
                                   "specified in world coordinates and scales with distance from the camera (false)")},
       {"color", colour("Color of the text")},
       {"text", string("Text")}});
}

}  // namespace

nlohmann::json frameTransformsSchema() {
  json transform = object("foxglove.FrameTransform", "A transform between two reference frames in 3D space",
                          {{"timestamp", time("Timestamp of transform")},
                           {"parent_frame_id", string("Name of the parent frame")},
                           {"child_frame_id", string("Name of the child frame")},
                           {"translation", vector3("Translation component of the transform")},
                           {"rotation", quaternion("Rotation component of the transform")}});
  return object("foxglove.FrameTransforms", "An array of FrameTransform messages",
                {{"transforms", array(std::move(transform), "Array of transforms")}});
}

nlohmann::json sceneUpdateSchema() {
  json deletion_type{
      {"title", "foxglove.SceneEntityDeletionType"},
      {"description", "Type of deletion action to perform"},
      {"oneOf",
       json::array(
           {{{"title", "MATCHING_ID"},
             {"const", 0},
             {"description", "Delete the existing entity on the same topic that has the provided `id`"}},
            {{"title", "ALL"}, {"const", 1}, {"description", "Delete all existing entities on the same topic"}}})}};
  json deletion =
      object("foxglove.SceneEntityDeletion", "Command to remove previously published entities",
             {{"timestamp",
               time("Timestamp of the deletion. Only matching entities earlier than this timestamp will be deleted.")},
              {"type", std::move(deletion_type)},
              {"id", string("Identifier which must match if `type` is `MATCHING_ID`.")}});
  json key_value = object("foxglove.KeyValuePair", "A key with its associated value",
                          {{"key", string("Key")}, {"value", string("Value")}});
  json entity = object(
      "foxglove.SceneEntity",
      "A visual element in a 3D scene. An entity may be composed of multiple primitives which all share the same frame "
      "of reference.",
      {{"timestamp", time("Timestamp of the entity")},
       {"frame_id", string("Frame of reference")},
       {"id",
        string(
            "Identifier for the entity. A entity will replace any prior entity on the same topic with the same `id`.")},
       {"lifetime",
        duration("Length of time (relative to `timestamp`) after which the entity should be automatically removed. "
                 "Zero value indicates the entity should remain visible until it is replaced or deleted.")},
       {"frame_locked", boolean("Whether the entity should keep its location in the fixed frame (false) or follow the "
                                "frame specified in `frame_id` as it moves relative to the fixed frame (true)")},
       {"metadata", array(std::move(key_value),
                          "Additional user-provided metadata associated with the entity. Keys must be unique.")},
       {"arrows", array(arrow(), "Arrow primitives")},
       {"cubes", array(cube(), "Cube primitives")},
       {"spheres", array(sphere(), "Sphere primitives")},
       {"cylinders", array(cylinder(), "Cylinder primitives")},
       {"lines", array(line(), "Line primitives")},
       {"triangles", array(triangles(), "Triangle list primitives")},
       {"texts", array(text(), "Text primitives")},
       {"models", array(model(), "Model primitives")}});
  return object("foxglove.SceneUpdate", "An update to the entities displayed in a 3D scene",
                {{"deletions", array(std::move(deletion), "Scene entities to delete")},
                 {"entities", array(std::move(entity), "Scene entities to add or replace")}});
}

nlohmann::json compressedImageSchema() {
  json data = string("Compressed image data");
  data["contentEncoding"] = "base64";
  return object("foxglove.CompressedImage", "A compressed image",
                {{"timestamp", time("Timestamp of image")},
                 {"frame_id", string("Frame of reference for the image. The origin of the frame is the optical "
                                     "center of the camera. +x points to the right in the image, +y points down, and "
                                     "+z points into the plane of the image.")},
                 {"data", std::move(data)},
                 {"format", string("Image format (jpeg, png, webp, avif)")}});
}

nlohmann::json viewStatusSchema() {
  json nullable_number{{"type", json::array({"number", "null"})}, {"description", "[m] or [1]; null when not finite"}};
  json target = object("reflex.Vector3", "hand target in the root frame [m], null when none",
                       {{"x", number("x [m]")}, {"y", number("y [m]")}, {"z", number("z [m]")}});
  target["type"] = json::array({"object", "null"});
  json arm = object("reflex.ViewArm", "one arm's status (ControlStatus.ArmStatus) and hand target",
                    {{"name", string("arm name from the controller configuration")},
                     {"valid", boolean("false until a ControlStatus arrived")},
                     {"distance", nullable_number},
                     {"blend_f", nullable_number},
                     {"zone",
                      {{"type", "string"},
                       {"enum", json::array({"free", "yellow", "orange", "red"})},
                       {"description", "zone of the closest pair"}}},
                     {"estop_latched", boolean("red zone reached, until reset")},
                     {"closest_a", string("segment of this arm in the closest pair")},
                     {"closest_b", string("the other segment of the closest pair")},
                     {"target_given", boolean("the hand has a target")},
                     {"target", std::move(target)},
                     {"target_object", string("object the hand points at")}});
  return object("reflex.ViewStatus", "Reflex controller status for the live view's plots",
                {{"timestamp", time("joint state stamp")},
                 {"d_a", number("yellow zone starts below this distance [m]")},
                 {"d_b", number("orange zone at or below this distance [m]")},
                 {"d_r", number("red zone (e-stop) at or below this distance [m]")},
                 {"arms", array(std::move(arm), "left, right")},
                 {"objects", integer("vision objects in the scene")},
                 {"protection", string("what protects the robot (ControllerProtection), \"\" if unknown")}});
}

}  // namespace reflex::view
