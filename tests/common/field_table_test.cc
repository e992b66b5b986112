// A config struct's field table: reading, writing, unknown keys, ranges, nested tables and the
// description all follow from one list.
#include "common/field_table.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace perch {
namespace {

struct Inner {
  double gain = 2.0;
};

struct Outer {
  int steps = 10;
  float rate = 0.5f;
  bool on = true;
  std::string name = "walk";
  std::vector<int> zones;
  Inner inner;
  int low = 1, high = 5;
  double degrees_as_radians = 0.0;
};

const FieldTable<Inner>& InnerFields() {
  static const FieldTable<Inner> t =
      FieldTable<Inner>().Add("gain", &Inner::gain, "a gain", Positive<double>());
  return t;
}

const FieldTable<Outer>& OuterFields() {
  static const FieldTable<Outer> t =
      FieldTable<Outer>()
          .Ignored("_comment", "free text")
          .Add("steps", &Outer::steps, "steps per update", AtLeast<int>(1))
          .Add("rate", &Outer::rate, "a rate",
               Satisfies<float>([](const float& v) { return v > 0 && v < 1; }, "must be in (0, 1)"))
          .Add("on", &Outer::on, "a switch")
          .Add("name", &Outer::name, "a name")
          .Add("zones", &Outer::zones, "a list")
          .Nested("inner", &Outer::inner, InnerFields(), "a nested section")
          .Add("low", &Outer::low, "lower bound")
          .Add("high", &Outer::high, "upper bound")
          .Custom(
              "deg", "an angle in degrees, held in radians",
              [](const Json& j, Outer& o, const std::string& ctx) {
                double d = 0;
                GetOptional(j, "deg", d, ctx);
                o.degrees_as_radians = d * 3.14159265358979 / 180.0;
              },
              [](const Outer& o, Json& j) {
                j["deg"] = o.degrees_as_radians * 180.0 / 3.14159265358979;
              })
          .Rule([](const Outer& o, const std::string& ctx) {
            return o.low <= o.high ? std::string() : ctx + ".low: must be <= high";
          });
  return t;
}

std::string ErrorOf(const Json& j) {
  try {
    OuterFields().Read(j, "cfg");
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "";
}

TEST(FieldTable, ReadsOverDefaultsAndWritesEveryField) {
  const Outer o = OuterFields().Read(
      Json::parse(R"({"steps": 20, "inner": {"gain": 3.5}, "deg": 90, "_comment": "x"})"), "cfg");
  EXPECT_EQ(o.steps, 20);
  EXPECT_FLOAT_EQ(o.rate, 0.5f);  // default kept
  EXPECT_DOUBLE_EQ(o.inner.gain, 3.5);
  EXPECT_NEAR(o.degrees_as_radians, 1.5707963, 1e-6);
  const Json w = OuterFields().Write(o);
  EXPECT_EQ(w["steps"], 20);
  EXPECT_EQ(w["inner"]["gain"], 3.5);
  EXPECT_NEAR(w["deg"].get<double>(), 90.0, 1e-9);
  EXPECT_FALSE(w.contains("_comment"));
  // What is written reads back to the same struct, and writes the same JSON again.
  EXPECT_EQ(OuterFields().Write(OuterFields().Read(w, "cfg")), w);
  // Every named field is in the output: one list gives reading and writing alike.
  for (const std::string& n : OuterFields().Names()) {
    if (n != "_comment") {
      EXPECT_TRUE(w.contains(n)) << n;
    }
  }
}

TEST(FieldTable, RefusesUnknownKeysWrongTypesAndValuesOutOfRange) {
  EXPECT_EQ(ErrorOf(Json::parse(R"({"stpes": 3})")), "cfg: unknown field 'stpes'");
  EXPECT_EQ(ErrorOf(Json::parse(R"({"inner": {"gian": 1}})")), "cfg.inner: unknown field 'gian'");
  EXPECT_THAT(ErrorOf(Json::parse(R"({"steps": 1.5})")),
              testing::HasSubstr("cfg.steps: expected an integer"));
  EXPECT_EQ(ErrorOf(Json::parse(R"({"steps": 0})")),
            "cfg.steps: must be >= 1.000000, got 0.000000");
  EXPECT_EQ(ErrorOf(Json::parse(R"({"rate": 1.5})")), "cfg.rate: must be in (0, 1)");
  EXPECT_EQ(ErrorOf(Json::parse(R"({"inner": {"gain": -1}})")), "cfg.inner.gain: must be > 0");
  EXPECT_EQ(ErrorOf(Json::parse(R"({"low": 6})")), "cfg.low: must be <= high");
  EXPECT_THAT(ErrorOf(Json::parse(R"({"deg": "ninety"})")), testing::HasSubstr("cfg.deg"));
  EXPECT_THAT(ErrorOf(Json::parse("[1, 2]")), testing::HasSubstr("cfg: expected an object"));
  EXPECT_EQ(ErrorOf(Json::parse(R"({"steps": 3, "zones": [1, 2]})")), "");
}

TEST(FieldTable, DescribesEachFieldOnceWithDefaultRuleAndDoc) {
  const Json d = OuterFields().Describe();
  ASSERT_EQ(d.size(), OuterFields().Names().size());
  auto row = [&](const std::string& name) {
    for (const Json& r : d) {
      if (r["name"] == name) return r;
    }
    return Json();
  };
  EXPECT_EQ(row("steps")["default"], 10);
  EXPECT_EQ(row("steps")["rule"], "must be >= 1.000000");
  EXPECT_EQ(row("steps")["doc"], "steps per update");
  EXPECT_EQ(row("name")["default"], "walk");
  EXPECT_FALSE(row("on").contains("rule"));
  // A nested table lists its own rows.
  ASSERT_TRUE(row("inner").contains("fields"));
  EXPECT_EQ(row("inner")["fields"][0]["name"], "gain");
  EXPECT_EQ(row("inner")["fields"][0]["default"], 2.0);
}

}  // namespace
}  // namespace perch
