// `iso verify FILE`: check every byte of a file; exit 0 only when it is sound.
#include <fmt/core.h>

#include <nlohmann/json.hpp>

#include "iso/error.h"
#include "iso/verify.h"
#include "tools/iso/commands.h"
#include "tools/iso/text.h"

namespace iso::cli {
namespace {

struct Outcome {
  std::vector<std::string> problems;
  std::vector<nlohmann::json> problemJson;
  uint64_t chunks = 0, bytes = 0;
};

Outcome check(const std::string& file) {
  Outcome outcome;
  try {
    const Reader reader = Reader::open(file);
    const VerifyResult result = verifyFile(reader);
    for (const VerifyProblem& p : result.problems) {
      outcome.problems.push_back(describe(reader, p));
      outcome.problemJson.push_back(
          {{"chunk", p.chunk ? nlohmann::json(*p.chunk) : nlohmann::json()},
           {"offset", p.offset},
           {"reason", p.reason}});
    }
    if (nlohmann::json::parse(reader.metadata(), nullptr, false).is_object() == false) {
      const uint64_t at = reader.fileSize() - kTrailerSize - reader.metadata().size();
      outcome.problems.push_back(fmt::format("byte {}: metadata is not a JSON object", at));
      outcome.problemJson.push_back(
          {{"chunk", nullptr}, {"offset", at}, {"reason", "metadata is not a JSON object"}});
    }
    outcome.chunks = result.chunksChecked;
    outcome.bytes = result.bytesChecked;
  } catch (const FileError& error) {
    const std::string where = error.offset() ? fmt::format("byte {}: ", *error.offset()) : "";
    outcome.problems.push_back(where + error.reason());
    outcome.problemJson.push_back(
        {{"chunk", nullptr},
         {"offset", error.offset() ? nlohmann::json(*error.offset()) : nlohmann::json()},
         {"reason", error.reason()}});
  }
  return outcome;
}

}  // namespace

void addVerifyCommand(CLI::App& app, int& exitCode) {
  struct Options {
    std::string file;
    bool json = false;
  };
  auto options = std::make_shared<Options>();
  CLI::App* command = app.add_subcommand(
      "verify", "Check every byte of an .iso file (structure, checksums, compressed streams)");
  command->add_option("file", options->file, ".iso file")->required();
  command->add_flag("--json", options->json, "Print the outcome as JSON");
  command->callback([options, &exitCode] {
    exitCode = runGuarded("verify", [&] {
      const Outcome outcome = check(options->file);
      const bool ok = outcome.problems.empty();
      if (options->json) {
        nlohmann::json j = {{"file", options->file},
                            {"ok", ok},
                            {"chunks_checked", outcome.chunks},
                            {"bytes_checked", outcome.bytes},
                            {"problems", outcome.problemJson}};
        fmt::print("{}\n", j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace));
      } else if (ok) {
        fmt::print("{}: ok ({} chunks, {} bytes checked)\n", options->file,
                   withSeparators(outcome.chunks), withSeparators(outcome.bytes));
      } else {
        for (const std::string& p : outcome.problems)
          fmt::print(stderr, "{}: {}\n", options->file, p);
        fmt::print(stderr, "{}: FAILED ({} problem{})\n", options->file, outcome.problems.size(),
                   outcome.problems.size() == 1 ? "" : "s");
      }
      return ok ? kExitOk : kExitFailure;
    });
  });
}

}  // namespace iso::cli
