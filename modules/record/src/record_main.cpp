// reflex_record: record Reflex topics to a crash-safe file, play it back, export CSV, show info.
#include "cli.hpp"
#include "reflex/common/run_main.hpp"

#include <cstdio>
#include <string>

int main(int argc, char** argv) {
  CLI::App app{
      "reflex_record: the Reflex bus recorder.\n"
      "  reflex_record record -o run.mcap [--topic reflex/control_status ...]  record (Ctrl-C stops)\n"
      "  reflex_record play run.mcap [--rate 2] [--loop] [--start 5]           play back (also: reflex_play)\n"
      "  reflex_record export run.mcap --topic reflex/control_status --csv status.csv\n"
      "  reflex_record info run.mcap [--print 10]\n"
      "  reflex_record convert run.rfx run.mcap [--compression lz4]\n"
      "Recordings are MCAP (open them in Foxglove: File > Open local file; one channel per topic, CDR\n"
      "messages, OMG IDL schemas from idl/; plus the scene channels /tf and /reflex/scene, JSON, made from\n"
      "the joint state and the robot model (--urdf; --no-scene: none), so a 3D panel shows the robot in\n"
      "frame 'world') or, for names ending in .rfx or --format rfx, the Reflex log\n"
      "format. Both stay readable after kill -9: MCAP loses the open chunk (--chunk-ms), .rfx the\n"
      "records of the last --flush-ms. play, export and info read both (detected by the first bytes)."};
  app.require_subcommand(1);
  auto* rec = app.add_subcommand("record", "record topics to a file");
  auto* play = app.add_subcommand(
      "play", "publish a recording again (rate, loop, start offset; observations only unless --commands)");
  auto* exp = app.add_subcommand("export", "write the samples of a topic as CSV");
  auto* info = app.add_subcommand("info", "topics, counts, duration and integrity of a recording");
  auto* conv = app.add_subcommand("convert", "copy a recording into another format (e.g. .rfx -> MCAP)");
  auto run_rec = reflex::record::cli::addRecord(*rec);
  auto run_play = reflex::record::cli::addPlay(*play);
  auto run_exp = reflex::record::cli::addExport(*exp);
  auto run_info = reflex::record::cli::addInfo(*info);
  auto run_conv = reflex::record::cli::addConvert(*conv);
  if (argc > 1 && argv[1][0] != '-') {  // CLI11 would only say "a subcommand is required"
    const std::string sub = argv[1];
    if (sub != "record" && sub != "play" && sub != "export" && sub != "info" && sub != "convert") {
      std::fprintf(stderr, "reflex_record: unknown command '%s' (record, play, export, info, convert; see --help)\n",
                   argv[1]);
      return reflex::kExitRefused;
    }
  }
  if (const int code = reflex::parseCommandLine(app, argc, argv); code >= 0) return code;
  if (rec->parsed()) return run_rec();
  if (play->parsed()) return run_play();
  if (exp->parsed()) return run_exp();
  if (conv->parsed()) return run_conv();
  return run_info();
}
