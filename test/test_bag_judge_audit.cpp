// scripts/judge_audit.sh (docs/results.md, "the reload rule audited"): one short fine-tuning run
// through the script, to hold the plumbing that its table relies on: the verdict is the trainer
// rule's own line, the before/after columns come from eval.csv in the order `--against` writes it,
// and "better/worse/mixed" follows the numbers it prints.
#include <gtest/gtest.h>

#include <regex>
#include <string>

#include "cli_test_util.h"

namespace umvs {
namespace {

using test::run_shell;

TEST(JudgeAuditScript, ARunGivesTheRulesVerdictAndTheGroundTruthItNeverSaw) {
  const std::string work = test::temp_dir("judge_audit");
  const std::string command = "STEPS=3 SEEDS=1 ADAPT=photometric SCENES=room:301 THREADS=2 UMVS=" +
                              test::umvs_binary() + " bash " + UMVS_SOURCE_DIR + "/scripts/judge_audit.sh " + work;
  const test::Result r = run_shell(command);
  ASSERT_EQ(r.status, 0) << r.output;

  // | room 301, photometric, seed 1 | e0 / r0 / w0 -> e1 / r1 / w1 | depth | p0 -> p1 | c0% -> c1% | rule |
  const std::string num = "([0-9.]+)";
  const std::regex row("\\| room 301, photometric, seed 1 \\| " + num + " / " + num + " / " + num + " -> " + num +
                       " / " + num + " / " + num + " \\| (better|worse|mixed) \\| " + num + " -> " + num + " \\| " +
                       num + "% -> " + num + "% \\| (keep|reload) \\|");
  std::smatch m;
  ASSERT_TRUE(std::regex_search(r.output, m, row)) << r.output;
  const double e0 = std::stod(m[1]), r0 = std::stod(m[2]), w0 = std::stod(m[3]);
  const double e1 = std::stod(m[4]), r1 = std::stod(m[5]), w1 = std::stod(m[6]);
  // Scores of a real scene: errors in metres (a 320x256 rendered room), shares in percent.
  for (double e : {e0, e1}) EXPECT_TRUE(e > 0.0 && e < 5.0) << e;
  for (double rel : {r0, r1}) EXPECT_TRUE(rel > 0.0 && rel < 1.0) << rel;
  for (double w : {w0, w1}) EXPECT_TRUE(w > 0.0 && w < 100.0) << w;
  const int improved = (e1 < e0) + (r1 < r0) + (w1 > w0);
  const std::string depth = m[7];
  // The printed scores are rounded; the verdict on depth is made on the unrounded ones.
  if (e1 != e0 && r1 != r0 && w1 != w0) {
    EXPECT_EQ(depth, improved == 3 ? "better" : improved == 0 ? "worse" : "mixed") << m[0];
  }

  // The rule in the row is the one the scoring run printed (decide_reload), and the tally counts it.
  const std::string judged_log = test::file_bytes(work + "/judge/room_301_photometric_seed1.log");
  const std::string verdict = m[12];
  EXPECT_NE(judged_log.find("trainer rule: " + verdict + " "), std::string::npos) << judged_log;
  const bool served = verdict == "reload";
  const std::string tally = std::string("1 runs: served ") + (served && depth == "better" ? "1" : "0") +
                            " better, " + (served && depth == "mixed" ? "1" : "0") + " mixed, " +
                            (served && depth == "worse" ? "1" : "0") + " worse; kept " +
                            (!served && depth == "better" ? "1" : "0") + " better, " +
                            (!served && depth == "mixed" ? "1" : "0") + " mixed, " +
                            (!served && depth == "worse" ? "1" : "0") + " worse";
  EXPECT_NE(r.output.find(tally), std::string::npos) << r.output;
  // The fine-tuning itself never read the depth topic; only the scoring did.
  const std::string train_log = test::file_bytes(work + "/ft/room_301_photometric_seed1.log");
  EXPECT_NE(train_log.find("no ground truth"), std::string::npos) << train_log;
  EXPECT_NE(judged_log.find("with ground-truth depth (/camera/depth)"), std::string::npos) << judged_log;

  // A scene rendered with other textures is another scene: the next audit renders it again (and
  // fine-tunes and scores again) rather than reusing it under this audit's name.
  EXPECT_EQ(test::file_bytes(work + "/room_301.textures"), "none\n");
  test::write_bytes(work + "/room_301.textures", "installed\n");
  const test::Result again = run_shell(command);
  ASSERT_EQ(again.status, 0) << again.output;
  EXPECT_NE(again.output.find("was rendered with other textures than 'none': rendering it again"), std::string::npos)
      << again.output;
  EXPECT_EQ(test::file_bytes(work + "/room_301.textures"), "none\n");
  EXPECT_TRUE(std::regex_search(again.output, row)) << again.output;
}

}  // namespace
}  // namespace umvs
