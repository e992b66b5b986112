// A config struct's fields, each written once (issue 50): its JSON name, its member (hence its
// type, and its default: the struct's initializer), a doc line and, where it has one, its range.
// Reading (strict types, unknown keys refused), writing and the field list that
// `perch config --fields` prints all follow from the one table, as EnvPool's DefaultConfig()
// bindings and MuJoCo's X-macro field lists do.
//
//   const FieldTable<PpoConfig>& PpoFields() {
//     static const FieldTable<PpoConfig> t = FieldTable<PpoConfig>()
//         .Add("gamma", &PpoConfig::gamma, "discount", InRange(0.0, 1.0))
//         .Nested("obs_norm", &PpoConfig::obs_norm, NormalizerFields(), "observation normalizer");
//     return t;
//   }
#pragma once

#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "common/json_util.h"

namespace perch {

// A field's range: a test of the value and the rule it states ("must be > 0").
template <class V>
struct FieldRule {
  std::function<bool(const V&)> ok;
  std::string rule;
  // The error for a value out of range, after "CTX.field: " (default: the rule).
  std::function<std::string(const V&)> message;

  // The error names the value too: "must be in 1..64, got 0".
  FieldRule WithValue() const {
    FieldRule r = *this;
    const std::string text = rule;
    r.message = [text](const V& v) { return text + ", got " + std::to_string(v); };
    return r;
  }
};

// Common rules. The messages are the ones the hand-written checks used.
template <class V>
FieldRule<V> Positive() {
  return {[](const V& v) { return v > 0; }, "must be > 0", nullptr};
}
template <class V>
FieldRule<V> NonNegative() {
  return {[](const V& v) { return v >= 0; }, "must be >= 0", nullptr};
}
// lo <= v <= hi, stated as `rule` ("must be in [0, 1]").
template <class V>
FieldRule<V> InRange(V lo, V hi, std::string rule) {
  return {[lo, hi](const V& v) { return v >= lo && v <= hi; }, std::move(rule), nullptr};
}
template <class V>
FieldRule<V> Satisfies(std::function<bool(const V&)> ok, std::string rule) {
  return {std::move(ok), std::move(rule), nullptr};
}
// v >= lo, its error naming the value ("must be >= 1.000000, got 0.000000").
template <class V>
FieldRule<V> AtLeast(double lo) {
  const std::string rule = "must be >= " + std::to_string(lo);
  return {[lo](const V& v) { return static_cast<double>(v) >= lo; }, rule,
          [rule](const V& v) { return rule + ", got " + std::to_string(static_cast<double>(v)); }};
}

template <class T>
class FieldTable {
 public:
  struct Field {
    std::string name;
    std::string doc;
    std::string rule;  // "" when any value of the type is accepted
    // Reads the field from the whole object `j` when present; `ctx` names the object.
    std::function<void(const Json& j, T& t, const std::string& ctx)> read;
    // Writes the field into `j` (a field may leave itself out, e.g. an unset optional).
    std::function<void(const T& t, Json& j)> write;
    // "" or "CTX.name: rule" for a value out of range.
    std::function<std::string(const T& t, const std::string& ctx)> check;
    // A nested table's own rows (Describe).
    std::function<Json()> describe;
  };

  // A plain field of any type GetOptional reads (integers strictly, floats, bools, strings,
  // vectors of them).
  template <class M>
  FieldTable& Add(const char* name, M T::*member, const char* doc) {
    return Add(name, member, doc, FieldRule<M>{});
  }
  template <class M>
  FieldTable& Add(const char* name, M T::*member, const char* doc, FieldRule<M> rule) {
    Field f;
    f.name = name;
    f.doc = doc;
    f.rule = rule.rule;
    const std::string key = name;
    f.read = [key, member](const Json& j, T& t, const std::string& ctx) {
      GetOptional(j, key.c_str(), t.*member, ctx);
    };
    f.write = [key, member](const T& t, Json& j) { j[key] = t.*member; };
    if (rule.ok) {
      f.check = [key, member, rule](const T& t, const std::string& ctx) {
        if (rule.ok(t.*member)) return std::string();
        return ctx + "." + key + ": " + (rule.message ? rule.message(t.*member) : rule.rule);
      };
    }
    fields_.push_back(std::move(f));
    return *this;
  }

  // A nested struct with its own table: read strictly under "CTX.name".
  template <class M>
  FieldTable& Nested(const char* name, M T::*member, const FieldTable<M>& table, const char* doc) {
    Field f;
    f.name = name;
    f.doc = doc;
    const std::string key = name;
    f.read = [key, member, &table](const Json& j, T& t, const std::string& ctx) {
      auto it = j.find(key);
      if (it != j.end()) t.*member = table.Read(*it, ctx + "." + key, t.*member);
    };
    f.write = [key, member, &table](const T& t, Json& j) { j[key] = table.Write(t.*member); };
    f.describe = [member, &table]() { return table.Describe(T().*member); };
    fields_.push_back(std::move(f));
    return *this;
  }

  // A field with its own reading, called when the key is present with the whole object and its
  // context (so that GetOptional(j, name, ..., ctx) names "CTX.name"), and its own writing (which
  // may leave the field out).
  FieldTable& Custom(const char* name, const char* doc,
                     std::function<void(const Json& j, T& t, const std::string& ctx)> read,
                     std::function<void(const T& t, Json& j)> write) {
    Field f;
    f.name = name;
    f.doc = doc;
    const std::string key = name;
    f.read = [key, read](const Json& j, T& t, const std::string& ctx) {
      if (j.contains(key)) read(j, t, ctx);
    };
    f.write = std::move(write);
    fields_.push_back(std::move(f));
    return *this;
  }

  // As Custom, but read also when the key is absent (a field whose value sets others' defaults,
  // such as a reward variant, applies its default too).
  FieldTable& CustomAlways(const char* name, const char* doc,
                           std::function<void(const Json& j, T& t, const std::string& ctx)> read,
                           std::function<void(const T& t, Json& j)> write) {
    Field f;
    f.name = name;
    f.doc = doc;
    f.read = std::move(read);
    f.write = std::move(write);
    fields_.push_back(std::move(f));
    return *this;
  }

  // A key that is accepted and ignored (a "_comment").
  FieldTable& Ignored(const char* name, const char* doc) {
    Field f;
    f.name = name;
    f.doc = doc;
    f.read = [](const Json&, T&, const std::string&) {};
    f.write = [](const T&, Json&) {};
    fields_.push_back(std::move(f));
    return *this;
  }

  // Rows shared by several tables: f(*this) adds them (tasks/config_fields.h).
  template <class F>
  FieldTable& With(F f) {
    f(*this);
    return *this;
  }

  // A rule across fields, checked after every field is read: "" or the whole message.
  FieldTable& Rule(std::function<std::string(const T& t, const std::string& ctx)> rule) {
    rules_.push_back(std::move(rule));
    return *this;
  }

  // Reads `j` over `defaults`: unknown keys, wrong types and values out of range throw
  // ConfigError naming "CTX.field".
  T Read(const Json& j, const std::string& ctx, T defaults = T()) const {
    if (!j.is_object()) throw ConfigError(ctx + ": expected an object, got " + j.dump());
    CheckKnownKeys(j, Names(), ctx);
    for (const Field& f : fields_) f.read(j, defaults, ctx);
    Check(defaults, ctx);
    return defaults;
  }

  // Throws the first range or cross-field rule `t` breaks.
  void Check(const T& t, const std::string& ctx) const {
    for (const Field& f : fields_) {
      if (!f.check) continue;
      const std::string e = f.check(t, ctx);
      if (!e.empty()) throw ConfigError(e);
    }
    for (const auto& r : rules_) {
      const std::string e = r(t, ctx);
      if (!e.empty()) throw ConfigError(e);
    }
  }

  Json Write(const T& t) const {
    Json j = Json::object();
    for (const Field& f : fields_) f.write(t, j);
    return j;
  }

  std::vector<std::string> Names() const {
    std::vector<std::string> n;
    for (const Field& f : fields_) n.push_back(f.name);
    return n;
  }

  // The table as data: [{name, default, doc, rule}] (a nested table's rows under "fields"
  // instead of a default), defaults from T() (or `defaults`).
  Json Describe(const T& defaults = T()) const {
    const Json values = Write(defaults);
    Json out = Json::array();
    for (const Field& f : fields_) {
      Json row{{"name", f.name}, {"doc", f.doc}};
      if (f.describe) {
        row["fields"] = f.describe();
      } else {
        row["default"] = values.contains(f.name) ? values[f.name] : Json();
      }
      if (!f.rule.empty()) row["rule"] = f.rule;
      out.push_back(row);
    }
    return out;
  }

  const std::vector<Field>& fields() const { return fields_; }

 private:
  std::vector<Field> fields_;
  std::vector<std::function<std::string(const T&, const std::string&)>> rules_;
};

}  // namespace perch
