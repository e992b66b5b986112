// Friendlier command-line errors than CLI11's (issue 18): an unknown option or subcommand is
// named, with the nearest valid name suggested ("--conifg: unknown option of 'perch train'; did
// you mean --config?"), before CLI11 would report a missing required option instead.
#pragma once

#include <string>

#include <CLI/CLI.hpp>

namespace perch {

// Levenshtein distance (insertions, deletions, substitutions).
int EditDistance(const std::string& a, const std::string& b);

// "" when argv names only known subcommands and options; otherwise the message to print.
std::string CheckCommandLine(const CLI::App& root, int argc, const char* const* argv);

// Removes "--data-dir DIR" / "--data-dir=DIR" (accepted before or after the subcommand) from
// argv, returning DIR ("" when absent). Throws std::runtime_error when DIR is missing.
std::string TakeDataDirFlag(int* argc, char** argv);

}  // namespace perch
