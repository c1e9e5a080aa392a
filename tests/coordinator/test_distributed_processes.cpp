// The distributed service as real processes: `poseforest coordinator` and `poseforest worker`
// started from the built program. A worker SIGKILLed mid-job, and a coordinator SIGKILLed and
// restarted with --resume, still give LocalTrainer's forest byte for byte (restarted at once,
// and after the workers replaced their DDS participants on the coordinator's lost lease).
// A worker SIGKILLed while a round waits for its reply: the round is asked again.
// Five worker processes (uneven shards, subtree hand-off) give `poseforest train`'s forest.
// Bad --peers / --interfaces values are refused with an error naming the flag and the value.
// A job's dds section gives the coordinator and `worker --job-file` their domain and transport.
// A worker of another build refuses the job, and the coordinator names it and why.

#include <catch2/catch.hpp>
#include <filesystem>
#include <fstream>
#include <iterator>

#include "tests/coordinator/dist_test_util.h"
#include "tests/proto/dds_test_util.h"
#include "tests/support/process.h"

using namespace poseforest;
using namespace poseforest::coordinator::testing;
using poseforest::proto::dds::testing::Child;
using poseforest::proto::dds::testing::HelperDir;
using namespace std::chrono_literals;

namespace {
std::string Program() { return (HelperDir() / "poseforest").string(); }

void StartWorker(Child& c, uint32_t domain, const std::string& job_id, const std::string& id) {
  std::string error;
  REQUIRE(c.Start({Program(), "worker", "--domain", std::to_string(domain), "--job", job_id, "--id", id},
                  &error));
}
}  // namespace

TEST_CASE("coordinator --local-workers 2 writes LocalTrainer's forest (shm and udp profiles)",
          "[distributed][integration][slow]") {
  const std::string text = TinyJobText(1, 6);
  const std::vector<uint8_t> reference = ReferenceBytes(ParseJob(text));
  for (const std::string profile : {"shm", "udp"}) {
    DYNAMIC_SECTION("profile " << profile) {
      TempDir dir("pf-dist-local-" + profile);
      std::ofstream(dir.path / "job.textproto") << text;
      Child coord;
      std::string error;
      REQUIRE(coord.Start({Program(), "coordinator", (dir.path / "job.textproto").string(), "--out",
                           (dir.path / "forest.pff").string(), "--local-workers", "2", "--profile", profile,
                           "--domain", std::to_string(Domain(profile == "shm" ? 21 : 22)), "--status-file",
                           (dir.path / "status.json").string()},
                          &error));
      auto rc = coord.Wait(120s);
      INFO(coord.output());
      REQUIRE(rc.has_value());
      REQUIRE(*rc == 0);
      CHECK(coord.output().find("tree 0 level 0:") != std::string::npos);
      CHECK(coord.output().find("2 workers alive") != std::string::npos);
      CHECK(ReadAll(dir.path / "forest.pff") == reference);
      CHECK(std::filesystem::exists(dir.path / "status.json"));
    }
  }
}

TEST_CASE("train --local-workers as pid 1 (a container's entrypoint): its workers stay and train",
          "[distributed][integration]") {
  // `docker run IMAGE` without --init makes the coordinator pid 1. Its local workers used to take
  // "parent is pid 1" for "parent gone" and exit at once (found by running the coordinator image):
  // 0 of 2 workers. A PID namespace of its own puts the coordinator at pid 1 without Docker.
  const std::string text = TinyJobText(1, 6);
  const std::vector<uint8_t> reference = ReferenceBytes(ParseJob(text));
  TempDir dir("pf-dist-pid1");
  std::ofstream(dir.path / "job.textproto") << text;
  Child coord;
  std::string error;
  REQUIRE(coord.Start({"unshare", "--pid", "--fork", "--mount-proc", Program(), "train",
                       (dir.path / "job.textproto").string(), "--out", (dir.path / "forest.pff").string(),
                       "--local-workers", "2", "--domain", std::to_string(Domain(77)), "--http", "off",
                       "--worker-wait-s", "30", "--quiet"},
                      &error));
  auto rc = coord.Wait(120s);
  INFO(coord.output());
  REQUIRE(rc.has_value());
  REQUIRE(*rc == 0);
  CHECK(coord.output().find("0 workers lost") != std::string::npos);
  CHECK(coord.output().find("is gone; exiting") == std::string::npos);
  // train's --quiet holds on the service too: no per-level lines.
  CHECK(coord.output().find("tree 0 level 0:") == std::string::npos);
  CHECK(ReadAll(dir.path / "forest.pff") == reference);
}

TEST_CASE("5 worker processes: the forest of `poseforest train`, byte for byte",
          "[distributed][integration][slow]") {
  // 12 frames per tree over 5 workers: shards of 3, 3, 2, 2, 2 frames; nodes of <= 300 samples
  // are trained whole by one worker (SubtreeTask) from level 1 on.
  TempDir dir("pf-dist-five");
  const std::string text = TinyJobText(2, 6, 300);
  std::ofstream(dir.path / "job.textproto") << text;
  // The single-process engine, as a user runs it.
  auto train = poseforest::testing::RunCommand(Program() + " train " + (dir.path / "job.textproto").string() +
                                               " --out " + (dir.path / "engine.pff").string() + " --quiet");
  INFO(train.output);
  REQUIRE(train.exit_code == 0);
  const std::vector<uint8_t> reference = ReadAll(dir.path / "engine.pff");
  REQUIRE(reference.size() > 1000);
  const uint32_t domain = Domain(29);
  const std::string job_id = "p-five-" + std::to_string(::getpid());
  Child w[5];
  for (int i = 0; i < 5; ++i) StartWorker(w[i], domain, job_id, "fw-" + std::to_string(i));
  Child coord;
  std::string error;
  REQUIRE(coord.Start({Program(), "coordinator", (dir.path / "job.textproto").string(), "--out",
                       (dir.path / "forest.pff").string(), "--domain", std::to_string(domain), "--job-id",
                       job_id, "--min-workers", "5", "--http", "off"},
                      &error));
  auto rc = coord.Wait(120s);
  INFO(coord.output());
  // The workers' side, for a failure (one CI run saw "2 of 5 workers after 60000 ms" here).
  std::string workers_said;
  for (int i = 0; i < 5; ++i) workers_said += "worker fw-" + std::to_string(i) + ":\n" + w[i].OutputNow() + "\n";
  INFO(workers_said);
  REQUIRE(rc.has_value());
  REQUIRE(*rc == 0);
  CHECK(coord.output().find("5 workers alive") != std::string::npos);
  CHECK(coord.output().find("0 workers lost") != std::string::npos);
  CHECK(ReadAll(dir.path / "forest.pff") == reference);
  for (int i = 0; i < 5; ++i) {
    CHECK(w[i].Wait(10s).has_value());  // it exits on JOB_DONE
    INFO("worker " << i << ": " << w[i].output());
    CHECK(w[i].output().find("shard of ") != std::string::npos);  // and it held frames
  }
}

TEST_CASE("the job's dds section: coordinator and `worker --job-file` meet on its domain and transport",
          "[distributed][integration][slow]") {
  TempDir dir("pf-dist-jobdds");
  const uint32_t domain = Domain(33);
  const std::string text = TinyJobText(1, 5, 300) + "dds { domain: " + std::to_string(domain) +
                           " profile: \"udp\" peers: \"127.0.0.1\" }\n";
  const std::string job = (dir.path / "job.textproto").string();
  std::ofstream(job) << text;
  const std::vector<uint8_t> reference = ReferenceBytes(ParseJob(text));
  auto run = [](const std::string& args) { return poseforest::testing::RunCommand(Program() + " " + args); };
  // What each would use: the job's settings; the command line's where it gives them (the
  // transport whole: --profile shm drops the job's peers too).
  auto coord_cfg = run("coordinator " + job + " --out " + (dir.path / "f.pff").string() + " --check-config");
  INFO(coord_cfg.output);
  REQUIRE(coord_cfg.exit_code == 0);
  CHECK(coord_cfg.output.find("DDS domain " + std::to_string(domain) + ", UDP, initial peers 127.0.0.1") !=
        std::string::npos);
  const auto at = coord_cfg.output.find("job job-");
  REQUIRE(at != std::string::npos);
  const std::string job_id = coord_cfg.output.substr(at + 4, coord_cfg.output.find(' ', at + 4) - at - 4);
  auto worker_cfg = run("worker --job-file " + job + " --check-config");
  INFO(worker_cfg.output);
  REQUIRE(worker_cfg.exit_code == 0);
  CHECK(worker_cfg.output.find("job " + job_id + ",") != std::string::npos);  // the coordinator's job id
  CHECK(worker_cfg.output.find("DDS domain " + std::to_string(domain) + ", UDP, initial peers 127.0.0.1") !=
        std::string::npos);
  auto flags_win = run("worker --job-file " + job + " --check-config --domain 7 --profile shm --job other");
  INFO(flags_win.output);
  REQUIRE(flags_win.exit_code == 0);
  CHECK(flags_win.output.find("job other,") != std::string::npos);
  CHECK(flags_win.output.find("DDS domain 7, shared memory") != std::string::npos);
  // The job, for real: no --domain, --job, --profile or --peers anywhere.
  Child w[2];
  std::string error;
  for (int i = 0; i < 2; ++i)
    REQUIRE(w[i].Start({Program(), "worker", "--job-file", job, "--id", "jw-" + std::to_string(i)}, &error));
  Child coord;
  REQUIRE(coord.Start({Program(), "coordinator", job, "--out", (dir.path / "forest.pff").string(), "--min-workers",
                       "2", "--http", "off"},
                      &error));
  auto rc = coord.Wait(120s);
  INFO(coord.output());
  REQUIRE(rc.has_value());
  REQUIRE(*rc == 0);
  CHECK(coord.output().find("2 workers alive") != std::string::npos);
  CHECK(ReadAll(dir.path / "forest.pff") == reference);
  for (Child& c : w) CHECK(c.Wait(10s).has_value());  // they left on JOB_DONE
  // Bad settings in the job: errors name the job file and the field.
  for (const auto& [dds, message] : std::vector<std::pair<std::string, std::string>>{
           {"dds { domain: 300 }", "dds.domain 300 is not a DDS domain id"},
           {"dds { profile: \"tcp\" }", "dds.profile \"tcp\" is not shm, udp or default"},
           {"dds { profile: \"udp\" peers: \"10.0.0\" }", "(transport settings from the dds section of " + job},
           {"dds { dds_xml: \"missing.xml\" dds_profile: \"p\" }", "missing.xml"}}) {
    std::ofstream(job) << TinyJobText(1, 5, 300) << dds << "\n";
    for (const std::string& cmd : {"coordinator " + job + " --out " + (dir.path / "g.pff").string(),
                                  "worker --job-file " + job}) {
      auto bad = run(cmd + " --check-config");
      INFO(cmd << " with " << dds << ": " << bad.output);
      CHECK(bad.exit_code == 2);
      CHECK(bad.output.find(message) != std::string::npos);
    }
  }
}

TEST_CASE("SIGKILL of one of 3 worker processes mid-job: same forest", "[distributed][integration][slow]") {
  // Without and with subtree hand-off (nodes of <= 300 samples trained whole by one worker,
  // from about level 2 on: the kill may hit a worker holding a SubtreeTask).
  for (uint64_t subtree : {uint64_t(0), uint64_t(300)}) {
    DYNAMIC_SECTION("subtree_max_samples " << subtree) {
      TempDir dir("pf-dist-kill");
      const std::string text = TinyJobText(2, 6, subtree);
      std::ofstream(dir.path / "job.textproto") << text;
      const std::vector<uint8_t> reference = ReferenceBytes(ParseJob(text));
      const uint32_t domain = Domain(23);
      const std::string job_id = "p-kill-" + std::to_string(::getpid()) + "-" + std::to_string(subtree);
      Child w[3];
      for (int i = 0; i < 3; ++i) StartWorker(w[i], domain, job_id, "pw-" + std::to_string(i));
      Child coord;
      std::string error;
      REQUIRE(coord.Start({Program(), "coordinator", (dir.path / "job.textproto").string(), "--out",
                           (dir.path / "forest.pff").string(), "--domain", std::to_string(domain), "--job-id",
                           job_id, "--min-workers", "3"},
                          &error));
      auto line = coord.WaitForLine("tree 0 level 1:", 90s);
      INFO(coord.output());
      REQUIRE(line.has_value());
      w[1].Kill(SIGKILL);
      // Done without it, the coordinator waits a while for lost workers to come back (one that
      // replaces its DDS participant is lost for a moment). A new pw-1 started then hears
      // JOB_DONE (the status topic replays it, or the coordinator says it again when pw-1 joins)
      // and leaves; without the wait nobody would tell it and it would wait for ever.
      auto waiting = coord.WaitForLine("lost worker(s) to come back and hear it: pw-1", 120s);
      INFO(coord.OutputNow());
      REQUIRE(waiting.has_value());
      Child again;
      StartWorker(again, domain, job_id, "pw-1");
      auto rc = coord.Wait(120s);
      INFO(coord.output());
      REQUIRE(rc.has_value());
      REQUIRE(*rc == 0);
      CHECK(coord.output().find("of 1 lost worker(s) came back") != std::string::npos);
      auto again_rc = again.Wait(20s);
      INFO("the new pw-1:\n" << again.OutputNow());
      REQUIRE(again_rc.has_value());
      CHECK(*again_rc == 0);
      CHECK(again.OutputNow().find("done") != std::string::npos);
      // The killed worker was noticed. (On a loaded CI machine a live worker's heartbeats can
      // also run late and it is counted lost and joins again - "2 workers lost" - with the
      // same forest; seen once in a fresh-clone CI.)
      CHECK(coord.output().find("worker pw-1 lost") != std::string::npos);
      CHECK(ReadAll(dir.path / "forest.pff") == reference);
      for (int i : {0, 2}) CHECK(w[i].Wait(10s).has_value());  // they exit on JOB_DONE
    }
  }
}

TEST_CASE("SIGKILL of the coordinator, restart with --resume: same forest",
          "[distributed][integration][slow]") {
  // Restarted at once (what a user's supervisor does), and restarted after the workers noticed
  // the coordinator gone. In the second case each worker replaces its DDS participant: Fast DDS
  // 2.9 keeps the shared-memory port it opened to the dead coordinator, and a restarted
  // coordinator that took the same participant id was never heard ("0 of 2 workers after
  // 60000 ms"; seen in CI, and 5 times in 120 restarts under load before the workers did so).
  // Third: restarted only after the workers, hearing no coordinator for 15 s, replaced their
  // participants once more (a participant made while the dead coordinator's ports were still
  // there opens those; CI saw a coordinator restarted then hear nobody).
  for (int mode : {0, 1, 2}) {
    const bool wait_for_workers = mode >= 1;
    DYNAMIC_SECTION((mode == 0   ? "restarted at once"
                     : mode == 1 ? "restarted after the workers saw it gone"
                                 : "restarted after the workers replaced their participants twice")) {
      TempDir dir("pf-dist-resume");
      const std::string text = TinyJobText(2, 6);
      std::ofstream(dir.path / "job.textproto") << text;
      const std::vector<uint8_t> reference = ReferenceBytes(ParseJob(text));
      const uint32_t domain = Domain(mode == 0 ? 25 : mode == 1 ? 26 : 28);
      const std::string job_id = "p-resume-" + std::to_string(::getpid()) + "-" + std::to_string(mode);
      Child w[2];
      for (int i = 0; i < 2; ++i) StartWorker(w[i], domain, job_id, "rw-" + std::to_string(i));
      const std::vector<std::string> args = {Program(),
                                             "coordinator",
                                             (dir.path / "job.textproto").string(),
                                             "--out",
                                             (dir.path / "forest.pff").string(),
                                             "--domain",
                                             std::to_string(domain),
                                             "--job-id",
                                             job_id,
                                             "--min-workers",
                                             "2",
                                             "--checkpoint",
                                             (dir.path / "ckpt").string()};
      {
        Child first;
        std::string error;
        REQUIRE(first.Start(args, &error));
        auto line = first.WaitForLine("tree 0 level 3:", 90s);
        INFO(first.output());
        REQUIRE(line.has_value());
        first.Kill(SIGKILL);
      }
      REQUIRE(std::filesystem::exists(dir.path / "ckpt" / "checkpoint.pb"));
      if (wait_for_workers) {
        // The coordinator's participant lease is 10 s.
        for (Child& c : w) {
          auto line = c.WaitForLine("DDS participant is gone: starting a new participant", 60s);
          INFO(c.OutputNow());
          CHECK(line.has_value());
        }
      }
      if (mode == 2)
        for (Child& c : w) {
          auto line = c.WaitForLine("starting a new DDS participant again", 40s);
          INFO(c.OutputNow());
          CHECK(line.has_value());
        }
      std::vector<std::string> resume = args;
      resume.push_back("--resume");
      Child second;
      std::string error;
      REQUIRE(second.Start(resume, &error));
      auto rc = second.Wait(120s);
      INFO(second.output());
      // The workers' side, for a failure.
      INFO("worker rw-0:\n" << w[0].OutputNow() << "\nworker rw-1:\n" << w[1].OutputNow());
      REQUIRE(rc.has_value());
      REQUIRE(*rc == 0);
      CHECK(second.output().find("tree 0 level 0:") == std::string::npos);  // resumed, not restarted
      CHECK(ReadAll(dir.path / "forest.pff") == reference);
      for (Child& c : w) CHECK(c.Wait(10s).has_value());  // they left on JOB_DONE
    }
  }
}

TEST_CASE("a worker process of another build is refused and named; POSEFOREST_BUILD_ID on both admits it",
          "[distributed][integration]") {
  TempDir dir("pf-dist-build");
  const std::string job = (dir.path / "job.textproto").string();
  std::ofstream(job) << TinyJobText(1, 4);
  const uint32_t domain = Domain(83);
  const std::string other = "POSEFOREST_BUILD_ID=poseforest 9.9.9 fedcba987654 GNU-99 x86_64";
  auto coordinator = [&](Child& c, const std::vector<std::string>& env, const std::string& out) {
    std::vector<std::string> argv = {"/usr/bin/env"};
    argv.insert(argv.end(), env.begin(), env.end());
    for (const std::string& a :
         {Program(), std::string("coordinator"), job, std::string("--out"), out, std::string("--domain"),
          std::to_string(domain), std::string("--job-id"), std::string("t-build"),
          std::string("--worker-wait-s"), std::string("8"), std::string("--http"), std::string("off")})
      argv.push_back(a);
    std::string error;
    REQUIRE(c.Start(argv, &error));
  };
  auto worker = [&](Child& c, const std::vector<std::string>& env) {
    std::vector<std::string> argv = {"/usr/bin/env"};
    argv.insert(argv.end(), env.begin(), env.end());
    for (const std::string& a :
         {Program(), std::string("worker"), std::string("--domain"), std::to_string(domain),
          std::string("--job"), std::string("t-build"), std::string("--id"), std::string("bw-1")})
      argv.push_back(a);
    std::string error;
    REQUIRE(c.Start(argv, &error));
  };
  {
    Child w, coord;
    worker(w, {other});
    coordinator(coord, {}, (dir.path / "refused.pff").string());
    auto rc = coord.Wait(60s);
    // The worker waits for other jobs: stopped, to read what it said.
    w.Kill(SIGTERM);
    (void)w.Wait(10s);
    INFO("coordinator:\n" << coord.output() << "\nworker:\n" << w.output());
    REQUIRE(rc.has_value());
    CHECK(*rc != 0);
    CHECK(coord.output().find("worker bw-1 on ") != std::string::npos);
    CHECK(coord.output().find("refused the job: the coordinator runs build \"poseforest ") !=
          std::string::npos);
    CHECK(coord.output().find("this worker \"poseforest 9.9.9 fedcba987654 GNU-99 x86_64\"") !=
          std::string::npos);
    CHECK(coord.output().find("0 of 1 workers") != std::string::npos);
    CHECK(coord.output().find("1 worker(s) not admitted: bw-1 on ") != std::string::npos);
    CHECK(w.output().find("job t-build refused: the coordinator runs build") != std::string::npos);
    CHECK(!std::filesystem::exists(dir.path / "refused.pff"));
  }
  // Builds known to train alike: the same POSEFOREST_BUILD_ID on every host.
  Child w, coord;
  worker(w, {other});
  coordinator(coord, {other}, (dir.path / "forest.pff").string());
  auto rc = coord.Wait(120s);
  INFO("coordinator:\n" << coord.output() << "\nworker:\n" << w.output());
  REQUIRE(rc.has_value());
  CHECK(*rc == 0);
  CHECK(coord.output().find("(build \"poseforest 9.9.9 fedcba987654 GNU-99 x86_64\")") != std::string::npos);
  CHECK(ReadAll(dir.path / "forest.pff") == ReferenceBytes(ParseJob(TinyJobText(1, 4))));
  CHECK(w.Wait(10s).has_value());
}

TEST_CASE("coordinator and worker: bad --peers / --interfaces get a clear error",
          "[distributed][integration]") {
  TempDir dir("pf-dist-peers");
  std::ofstream(dir.path / "job.textproto") << TinyJobText(1, 3);
  const std::string coordinator = Program() + " coordinator " + (dir.path / "job.textproto").string() +
                                  " --out " + (dir.path / "f.pff").string() + " ";
  struct Case {
    std::string cmd, expect;
  };
  const std::vector<Case> cases = {
      {coordinator + "--profile udp --peers 10.0.0.300", "'10.0.0.300' is not an IPv4 address"},
      // Host names are accepted (resolved at start-up; test_deploy); a malformed one is not, and is
      // refused before any lookup.
      {coordinator + "--profile udp --peers 10.0.0.1,host_1.example", "'host_1.example' is not a host name"},
      {coordinator + "--profile udp --peers 10.0.0.1:70000",
       "'10.0.0.1:70000' has port '70000': expected 1..65535"},
      {coordinator + "--profile udp --interfaces 10.0.0.1:7400", "--interfaces"},
      {coordinator + "--profile shm --peers 10.0.0.1", "--peers needs --profile udp"},
      {Program() + " worker --profile udp --peers 1.2.3", "'1.2.3' is not an IPv4 address"},
      {Program() + " worker --interfaces 10.0.0.2", "--interfaces needs --profile udp"},
  };
  for (const Case& c : cases) {
    auto r = poseforest::testing::RunCommand(c.cmd);
    INFO(c.cmd << "\n" << r.output);
    CHECK(r.exit_code == 2);
    CHECK(r.output.find(c.expect) != std::string::npos);
  }
  CHECK(!std::filesystem::exists(dir.path / "f.pff"));
}

TEST_CASE("SIGKILL of a worker while a level's round waits for it: noticed, asked again, same forest",
          "[distributed][integration][slow]") {
  TempDir dir("pf-dist-midlevel");
  const std::string text = TinyJobText(2, 6);
  std::ofstream(dir.path / "job.textproto") << text;
  const std::vector<uint8_t> reference = ReferenceBytes(ParseJob(text));
  const uint32_t domain = Domain(27);
  const std::string job_id = "p-midlevel-" + std::to_string(::getpid());
  Child w[2];
  for (int i = 0; i < 2; ++i) StartWorker(w[i], domain, job_id, "mw-" + std::to_string(i));
  // The coordinator holds before tree 0's level 0 while the pause file exists. Worker 1 is
  // stopped there and the file removed: the level's request goes out and worker 1 holds it
  // without answering (well inside its 1.5 s liveliness lease), so the kill lands while the round
  // waits for it. (Stopping it after a level line raced the next level on a fast machine.)
  const auto pause = dir.path / "pause";
  std::ofstream(pause) << "held by the test\n";
  Child coord;
  std::string error;
  REQUIRE(coord.Start({Program(), "coordinator", (dir.path / "job.textproto").string(), "--out",
                       (dir.path / "forest.pff").string(), "--domain", std::to_string(domain), "--job-id",
                       job_id, "--min-workers", "2", "--pause-file", pause.string()},
                      &error));
  auto line = coord.WaitForLine("paused (next: tree 0, level 0)", 90s);
  INFO(coord.output());
  REQUIRE(line.has_value());
  REQUIRE(::kill(w[1].pid(), SIGSTOP) == 0);
  std::filesystem::remove(pause);
  std::this_thread::sleep_for(400ms);
  w[1].Kill(SIGKILL);
  auto next = coord.WaitForLine("tree 0 level 0:", 60s);
  REQUIRE(next.has_value());
  CHECK(next->find("retries") != std::string::npos);  // the round was asked again
  auto rc = coord.Wait(120s);
  INFO(coord.output());
  REQUIRE(rc.has_value());
  REQUIRE(*rc == 0);
  CHECK(coord.output().find("worker mw-1 lost") != std::string::npos);  // (see the 3-worker case)
  CHECK(ReadAll(dir.path / "forest.pff") == reference);
  CHECK(w[0].Wait(10s).has_value());
}
