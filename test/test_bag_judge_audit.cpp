// scripts/experiments/judge_audit.sh (docs/results.md, "the reload rule audited"): one short fine-tuning run
// through the script, to hold the plumbing that its table relies on: the verdict is the trainer
// rule's own line, the before/after columns come from eval.csv in the order `--against` writes it,
// "better/worse/mixed" follows the numbers it prints, and the second pass is another path through
// the same scene that no run trained on.
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
                              test::umvs_binary() + " bash " + UMVS_SOURCE_DIR + "/scripts/experiments/judge_audit.sh " + work;
  const test::Result r = run_shell(command);
  ASSERT_EQ(r.status, 0) << r.output;

  // | room 301, photometric, seed 1 | e0 / r0 / w0 -> e1 / r1 / w1 | depth | (the same on the second
  // pass) | depth | p0 -> p1 | c0% -> c1% | rule |
  const std::string num = "([0-9.]+)";
  const std::string scores = num + " / " + num + " / " + num + " -> " + num + " / " + num + " / " + num +
                             " \\| (better|worse|mixed) \\| ";
  const std::regex row("\\| room 301, photometric, seed 1 \\| " + scores + scores + num + " -> " + num + " \\| " +
                       num + "% -> " + num + "% \\| (keep|reload) \\|");
  std::smatch m;
  ASSERT_TRUE(std::regex_search(r.output, m, row)) << r.output;
  std::string depth;
  for (int pass = 0; pass < 2; ++pass) {
    const int at = 1 + 7 * pass;
    const double e0 = std::stod(m[at]), r0 = std::stod(m[at + 1]), w0 = std::stod(m[at + 2]);
    const double e1 = std::stod(m[at + 3]), r1 = std::stod(m[at + 4]), w1 = std::stod(m[at + 5]);
    // Scores of a real scene: errors in metres (a 320x256 rendered room), shares in percent.
    for (double e : {e0, e1}) EXPECT_TRUE(e > 0.0 && e < 5.0) << e;
    for (double rel : {r0, r1}) EXPECT_TRUE(rel > 0.0 && rel < 1.0) << rel;
    for (double w : {w0, w1}) EXPECT_TRUE(w > 0.0 && w < 100.0) << w;
    const int improved = (e1 < e0) + (r1 < r0) + (w1 > w0);
    const std::string verdict = m[at + 6];
    // The printed scores are rounded; the verdict on depth is made on the unrounded ones.
    if (e1 != e0 && r1 != r0 && w1 != w0) {
      EXPECT_EQ(verdict, improved == 3 ? "better" : improved == 0 ? "worse" : "mixed") << m[0];
    }
    if (pass == 0) depth = verdict;
  }
  // The two passes are different images of one scene: the served model scores differently on them.
  EXPECT_NE(m[1].str() + m[2].str() + m[3].str(), m[8].str() + m[9].str() + m[10].str()) << m[0];

  // The rule in the row is the one the scoring run printed (decide_reload), and the tally counts it.
  const std::string judged_log = test::file_bytes(work + "/judge/room_301_photometric_seed1.log");
  const std::string verdict = m[19];
  EXPECT_NE(judged_log.find("trainer rule: " + verdict + " "), std::string::npos) << judged_log;
  const bool served = verdict == "reload";
  const std::string tally = std::string("1 runs (held-out keyframes): served ") + (served && depth == "better" ? "1" : "0") +
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
  // The second pass: the same scene on another path, every keyframe a reference judged against the others.
  EXPECT_NE(test::file_bytes(work + "/room_301.pass2/scene.txt").find("\npath_seed 1301\n"), std::string::npos);
  const std::string second_log = test::file_bytes(work + "/judge2/room_301_photometric_seed1.log");
  EXPECT_NE(second_log.find("10 posed images of 10, 10 keyframes (0 held out)"), std::string::npos) << second_log;
  EXPECT_NE(second_log.find("with ground-truth depth (/camera/depth)"), std::string::npos) << second_log;
  EXPECT_NE(r.output.find("1 runs (second pass): served "), std::string::npos) << r.output;

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
