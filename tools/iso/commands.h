// The sub-commands of the `iso` program. Each registers its options on the CLI11 app and, when
// selected, runs and sets the process exit code: 0 success, 1 failure, 2 usage error.
#pragma once

#include <CLI/CLI.hpp>

namespace iso::cli {

inline constexpr int kExitOk = 0;
inline constexpr int kExitFailure = 1;
inline constexpr int kExitUsage = 2;

// Runs body and turns an exception into its message on stderr ("iso COMMAND: ...") and an exit
// code: kExitUsage for a UsageError, kExitFailure for anything else (iso/error.h).
int runGuarded(const char* command, const std::function<int()>& body);

void addBakeCommand(CLI::App& app, int& exitCode);
void addConvertCommand(CLI::App& app, int& exitCode);
void addEvalCommand(CLI::App& app, int& exitCode);
void addExportCommand(CLI::App& app, int& exitCode);
void addGenCommand(CLI::App& app, int& exitCode);
void addInfoCommand(CLI::App& app, int& exitCode);
void addVerifyCommand(CLI::App& app, int& exitCode);
void addViewCommand(CLI::App& app, int& exitCode);

}  // namespace iso::cli
