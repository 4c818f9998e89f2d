// `iso`: the command-line program (tools/iso/commands.h lists the sub-commands).
#include <fmt/core.h>

#include <exception>
#include <new>

#include "iso/check.h"
#include "iso/error.h"
#include "iso/format.h"
#include "iso/version.h"
#include "tools/iso/commands.h"
#include "tools/iso/interrupt.h"

namespace iso::cli {

int runGuarded(const char* command, const std::function<int()>& body) {
  setInterruptMessage(std::string("iso ") + command + ": interrupted");
  try {
    return body();
  } catch (const std::exception& error) {  // the taxonomy: iso/error.h
    const bool memory = dynamic_cast<const std::bad_alloc*>(&error) != nullptr;
    fmt::print(stderr, "iso {}: {}\n", command, memory ? "out of memory" : error.what());
    return dynamic_cast<const UsageError*>(&error) ? kExitUsage : kExitFailure;
  }
}

}  // namespace iso::cli

int main(int argc, char** argv) {
  CLI::App app{
      "iso: compact level-of-detail surface assets (Implicit Surface Octrees) from 3D scans",
      "iso"};
  app.set_version_flag("--version", fmt::format("iso {} (.iso format {}.{})", ISO_VERSION,
                                                iso::kFormatMajor, iso::kFormatMinor));
  app.require_subcommand(1);
  app.footer("Run `iso COMMAND --help` for the options of a command.");
  int exitCode = iso::cli::kExitOk;
  iso::cli::addConvertCommand(app, exitCode);
  iso::cli::addEvalCommand(app, exitCode);
  iso::cli::addExportCommand(app, exitCode);
  iso::cli::addGenCommand(app, exitCode);
  iso::cli::addInfoCommand(app, exitCode);
  iso::cli::addVerifyCommand(app, exitCode);
  iso::cli::addBakeCommand(app, exitCode);
  iso::cli::addViewCommand(app, exitCode);
  iso::cli::installInterruptHandlers();  // Ctrl-C: no temporary file left, a line saying so
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& error) {
    const int code = app.exit(error);
    return code == 0 ? iso::cli::kExitOk : iso::cli::kExitUsage;
  }
  return exitCode;
}
