// reflex_play: publish a reflex_record recording (MCAP or .rfx) again (same as `reflex_record play`).
#include "cli.hpp"

int main(int argc, char** argv) {
  CLI::App app{
      "reflex_play: publish a reflex_record recording again with its original timing, scaled by --rate,\n"
      "from --start seconds, optionally --loop'ed (like `ros2 bag play`). Same as `reflex_record play`."};
  auto run = reflex::record::cli::addPlay(app);
  CLI11_PARSE(app, argc, argv);
  return run();
}
