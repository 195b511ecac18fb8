// reflex_play: publish a reflex_record recording (MCAP or .rfx) again (same as `reflex_record play`).
#include "cli.hpp"
#include "reflex/common/run_main.hpp"

int main(int argc, char** argv) {
  CLI::App app{
      "reflex_play: publish a reflex_record recording again with its original timing, scaled by --rate,\n"
      "from --start seconds, optionally --loop'ed (like `ros2 bag play`). Same as `reflex_record play`.\n"
      "Observations only by default (object targets, joint state, control status, robot state, heartbeats, ...):\n"
      "the command topics (hand targets, motion priority, body schema, walk command, joint command) are played\n"
      "only with --commands, so a replay never steers a live controller or robot."};
  auto run = reflex::record::cli::addPlay(app);
  if (const int code = reflex::parseCommandLine(app, argc, argv); code >= 0) return code;
  return run();
}
