// Field tables (common/field_table.h) as text for people: `perch config --fields` and
// `perch recipe fields` print their Describe() results this way.
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "common/json_util.h"

namespace perch {

// One field per line: the dotted name (each table's rows under its prefix, nested tables
// flattened), its default (aligned; wider than 24 columns pushes the rest), its doc and, in
// parentheses, its rule. `tables` holds {prefix, a Describe() result}.
std::string DescribedFieldsText(const std::vector<std::pair<std::string, Json>>& tables);

}  // namespace perch
