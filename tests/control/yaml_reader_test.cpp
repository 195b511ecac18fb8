// common::ConfigNode, the one YAML configuration reader (idl/common/include/reflex/common/yaml_reader.hpp),
// against hand-written documents whose positions were counted by hand: every error is the one format
// "FILE:LINE:COL: KEY.PATH: PROBLEM (value 'V', expected E)" (control/docs/configuration.md), thrown
// through the caller's error type; every getter refuses the wrong kind, a value outside its range, a
// missing required key and an unknown key, and accepts the ends of its range.
#include "reflex/common/yaml_reader.hpp"
#include "support/errors.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <stdexcept>

namespace reflex::common {
namespace {

struct OtherError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

template <class Fn>
std::string errorOf(Fn fn) {
  return reflex::testing::messageOf<ConfigError>(fn);
}

const char* kDoc =
    "gain: 2.5\n"            // line 1, value at column 7
    "name: left\n"           // line 2
    "flag: maybe\n"          // line 3, value at column 7
    "inner:\n"               // line 4
    "  limits: [1, x, 3]\n"  // line 5, the list at column 11, 'x' at column 15
    "  count: 12\n"          // line 6, value at column 10
    "items:\n"               // line 7
    "  - {id: 1}\n"          // line 8, the map at column 5
    "  - 7\n";               // line 9, value at column 5

TEST(YamlReader, ValuesInRangeAreRead) {
  const ConfigNode root = ConfigNode::loadString(kDoc, "doc.yaml");
  EXPECT_DOUBLE_EQ(root.number("gain", 0.0, 2.5, 2.5), 2.5);  // both ends of the range are inside
  EXPECT_DOUBLE_EQ(root.number("absent", 4.0, 0.0, 1.0), 4.0);
  EXPECT_EQ(root.string("name", ""), "left");
  EXPECT_EQ(root.child("inner").integer("count", 0, 12, 12), 12);
  EXPECT_EQ(root.at("items", "a list").elements().size(), 2U);
  EXPECT_EQ(root.child("inner").path(), "inner");
}

TEST(YamlReader, EveryErrorIsTheOneFormat) {
  const ConfigNode root = ConfigNode::loadString(kDoc, "doc.yaml");
  EXPECT_EQ(errorOf([&] { root.number("gain", 0.0, 0.0, 2.0, "m"); }),
            "doc.yaml:1:7: gain: out of range (value '2.5', expected a number in [0, 2] m)");
  EXPECT_EQ(errorOf([&] { root.number("name", 0.0, 0.0, 2.0); }),
            "doc.yaml:2:7: name: not a finite number (value 'left', expected a number in [0, 2])");
  EXPECT_EQ(errorOf([&] { root.boolean("flag", false); }),
            "doc.yaml:3:7: flag: not true or false (value 'maybe', expected true or false)");
  EXPECT_EQ(errorOf([&] { root.child("inner").at("limits", "").asNumbers(3); }),
            "doc.yaml:5:15: inner.limits[1]: not a finite number (value 'x', expected a list of 3 finite numbers)");
  EXPECT_EQ(errorOf([&] { root.child("inner").at("limits", "").asNumbers(2); }),
            "doc.yaml:5:11: inner.limits: has 3 numbers (value '[1, x, 3]', expected a list of 2 finite numbers)");
  EXPECT_EQ(errorOf([&] { root.child("inner").integer("count", 0, 0, 11); }),
            "doc.yaml:6:10: inner.count: out of range (value '12', expected an integer in [0, 11])");
  EXPECT_EQ(errorOf([&] { root.list("items"); }),
            "doc.yaml:9:5: items[1]: not a map (value '7', expected a map of keys)");
  EXPECT_EQ(errorOf([&] { root.child("inner").requiredNumber("gain", 0.0, 1.0); }),
            "doc.yaml:5:3: inner.gain: missing (expected a number in [0, 1])");
  EXPECT_EQ(errorOf([&] {
              root.choice("name", "left", {"up", "down"});
            }),
            "doc.yaml:2:7: name: unknown value (value 'left', expected one of up, down)");
  EXPECT_EQ(errorOf([&] {
              root.rejectUnknown({"gain", "name", "flag", "items"});
            }),
            "doc.yaml:4:1: inner: unknown key (expected one of gain, name, flag, items)");
  EXPECT_EQ(errorOf([&] { root.child("name"); }),
            "doc.yaml:2:7: name: not a map (value 'left', expected a map of keys)");
}

TEST(YamlReader, NonFiniteAndOverlongValues) {
  const ConfigNode root = ConfigNode::loadString("a: .nan\nb: .inf\nc: " + std::string(100, 'x') + "\n", "d.yaml");
  EXPECT_EQ(errorOf([&] { root.number("a", 0.0, -1e300, 1e300); }),
            "d.yaml:1:4: a: not a finite number (value '.nan', expected a number in [-1e+300, 1e+300])");
  EXPECT_NE(errorOf([&] { root.number("b", 0.0, -1e300, 1e300); }).find("(value '.inf'"), std::string::npos);
  // A long value is cut at 60 characters.
  EXPECT_EQ(
      errorOf([&] { root.number("c", 0.0, 0.0, 1.0); }),
      "d.yaml:3:4: c: not a finite number (value '" + std::string(57, 'x') + "...', expected a number in [0, 1])");
}

TEST(YamlReader, DocumentAndFileErrors) {
  EXPECT_EQ(errorOf([] { ConfigNode::loadString("- a\n- b\n", "l.yaml"); }),
            "l.yaml:1:1: (document): not a map of keys (value '[a, b]', expected a map of keys at the top level)");
  EXPECT_EQ(errorOf([] { ConfigNode::loadString("a: [1, 2\n", "s.yaml"); }).rfind("s.yaml:", 0), 0U);
  EXPECT_NE(errorOf([] { ConfigNode::loadString("a: [1, 2\n", "s.yaml"); }).find(": YAML syntax error: "),
            std::string::npos);
  EXPECT_NO_THROW(ConfigNode::loadString("", "e.yaml", &ConfigNode::raiseConfigError, /*allow_empty=*/true));
  EXPECT_NE(errorOf([] { ConfigNode::loadString("", "e.yaml"); }).find("e.yaml: (document): not a map of keys"),
            std::string::npos);
  EXPECT_EQ(errorOf([] { ConfigNode::loadFile("/nonexistent/c.yaml", "test configuration"); }),
            "/nonexistent/c.yaml: cannot open test configuration (No such file or directory)");
}

TEST(YamlReader, ErrorsAreThrownAsTheCallersType) {
  const ConfigNode::Raise raise = [](const std::string& m) { throw OtherError("other: " + m); };
  const ConfigNode root = ConfigNode::loadString("k: 1\n", "o.yaml", raise);
  try {
    EXPECT_EQ(root.string("k", ""), "1");
    root.number("k", 0.0, 2.0, 3.0);
    FAIL() << "no error";
  } catch (const OtherError& e) {
    EXPECT_STREQ(e.what(), "other: o.yaml:1:4: k: out of range (value '1', expected a number in [2, 3])");
  }
  // Children carry the caller's type too.
  const ConfigNode nested = ConfigNode::loadString("m:\n  k: x\n", "o.yaml", raise);
  EXPECT_THROW(nested.child("m").number("k", 0.0, 0.0, 1.0), OtherError);
}

TEST(YamlReader, PathsResolveAgainstTheFilesFolder) {
  const ConfigNode root = ConfigNode::loadString("p: x\n", "/a/b/c.yaml");
  EXPECT_EQ(root.resolvePath("d/e.yaml"), "/a/b/d/e.yaml");
  EXPECT_EQ(root.resolvePath("/abs.yaml"), "/abs.yaml");
}

}  // namespace
}  // namespace reflex::common
