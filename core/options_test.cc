#include "core/options.h"

#include <gtest/gtest.h>

#include <fstream>

#include "core/fs.h"

namespace headforge {
namespace {

struct Sample {
  double fps = 0.0;
  int max_frames = 10;
  bool flag = false;
  std::string name = "x";
  std::vector<std::string> videos;
  std::vector<int> offsets;
  int threads = 2;
};

void Bind(OptionSet* set, Sample* s) {
  set->Add("ingest.fps", &s->fps, "fps", "fps");
  set->Add("ingest.max_frames", &s->max_frames, "max", "max-frames");
  set->Add("ingest.flag", &s->flag, "flag", "flag");
  set->Add("ingest.name", &s->name, "name");
  set->Add("ingest.video", &s->videos, "videos", "video");
  set->Add("ingest.offsets", &s->offsets, "offsets", "offsets");
  set->Add("threads", &s->threads, "threads", "", OptionSet::Effect::kRuntime);
}

TEST(OptionSet, ShortFlagsDottedKeysAndDefaults) {
  Sample s;
  OptionSet set;
  Bind(&set, &s);
  ASSERT_TRUE(set.Parse({"--fps", "5", "--ingest.max_frames=7", "--flag", "--video", "a.mp4",
                         "b.mp4", "--offsets", "0,3,-1"})
                  .ok());
  EXPECT_DOUBLE_EQ(s.fps, 5.0);
  EXPECT_EQ(s.max_frames, 7);
  EXPECT_TRUE(s.flag);
  EXPECT_EQ(s.name, "x");
  EXPECT_EQ(s.videos, (std::vector<std::string>{"a.mp4", "b.mp4"}));
  EXPECT_EQ(s.offsets, (std::vector<int>{0, 3, -1}));
}

TEST(OptionSet, RejectsUnknownOptionsAndBadValues) {
  Sample s;
  OptionSet set;
  Bind(&set, &s);
  EXPECT_FALSE(set.Parse({"--no-such-option", "1"}).ok());
  Sample t;
  OptionSet set2;
  Bind(&set2, &t);
  const Status status = set2.Parse({"--fps", "fast"});
  ASSERT_FALSE(status.ok());
  EXPECT_NE(status.message().find("ingest.fps"), std::string::npos);
  EXPECT_NE(status.message().find("not a number"), std::string::npos);
}

TEST(OptionSet, ConfigFileUsesDottedKeysAndCommandLineWins) {
  const fs::path dir = fs::temp_directory_path() / "hf_options_test";
  fs::create_directories(dir);
  const fs::path ini = dir / "run.ini";
  {
    std::ofstream out(ini);
    out << "[ingest]\nfps = 10\nmax_frames = 3\nvideo = one.mp4\nvideo = two.mp4\n"
           "[track]\nunknown = 1\n";
  }
  Sample s;
  OptionSet set;
  Bind(&set, &s);
  ASSERT_TRUE(set.Parse({"--config", ini.string(), "--max-frames", "4"}).ok());
  EXPECT_DOUBLE_EQ(s.fps, 10.0);
  EXPECT_EQ(s.max_frames, 4);  // command line beats the file
  EXPECT_EQ(s.videos, (std::vector<std::string>{"one.mp4", "two.mp4"}));
  ASSERT_EQ(set.unknown_config_keys().size(), 1u);
  EXPECT_EQ(set.unknown_config_keys()[0], "track.unknown");
  fs::remove_all(dir);
}

TEST(OptionSet, AConfigAppliedBeneathTheCommandLineFillsOnlyWhatNobodyGave) {
  const fs::path dir = fs::temp_directory_path() / "hf_options_beneath";
  fs::create_directories(dir);
  const fs::path ini = dir / "recorded.ini";
  {
    std::ofstream out(ini);
    out << "[ingest]\nfps = 10\nmax_frames = 3\nvideo = one.mp4\n";
  }
  Sample s;
  OptionSet set;
  Bind(&set, &s);
  ASSERT_TRUE(set.Parse({"--max-frames", "4"}).ok());
  EXPECT_FALSE(set.WasGiven("ingest.fps"));
  ASSERT_TRUE(set.ApplyConfigBeneath(ini.string()).ok());
  EXPECT_DOUBLE_EQ(s.fps, 10.0);
  EXPECT_EQ(s.max_frames, 4);  // the command line stays
  EXPECT_EQ(s.videos, (std::vector<std::string>{"one.mp4"}));
  EXPECT_TRUE(set.WasGiven("ingest.fps"));
  EXPECT_TRUE(set.WasGiven("ingest.video"));
  {
    std::ofstream out(ini);
    out << "[ingest]\nfps = fast\n";
  }
  Sample t;
  OptionSet other;
  Bind(&other, &t);
  ASSERT_TRUE(other.Parse({}).ok());
  const Status bad = other.ApplyConfigBeneath(ini.string());
  EXPECT_FALSE(bad.ok());
  EXPECT_NE(bad.message().find("ingest.fps"), std::string::npos) << bad.message();
  EXPECT_FALSE(other.ApplyConfigBeneath((dir / "missing.ini").string()).ok());
  fs::remove_all(dir);
}

TEST(OptionSet, IniRoundTripReproducesValues) {
  Sample s;
  OptionSet set;
  Bind(&set, &s);
  ASSERT_TRUE(set.Parse({"--fps", "12.5", "--video", "a b.mp4", "c.mp4", "--threads", "7"}).ok());
  const fs::path ini = fs::temp_directory_path() / "hf_options_roundtrip.ini";
  ASSERT_TRUE(WriteFileAtomic(ini, set.ToIni()).ok());

  Sample t;
  OptionSet reread;
  Bind(&reread, &t);
  ASSERT_TRUE(reread.Parse({"--config", ini.string()}).ok());
  EXPECT_EQ(t.fps, s.fps);
  EXPECT_EQ(t.videos, s.videos);
  EXPECT_EQ(t.threads, 7);
  EXPECT_EQ(reread.ToIni(), set.ToIni());
  fs::remove(ini);
}

// Numbers are written as a reader expects them and read back exactly.
TEST(OptionSet, NumbersAreWrittenPlainlyAndReadBackExactly) {
  for (const auto& [given, written] : std::vector<std::pair<std::string, std::string>>{
           {"30", "fps = 30"}, {"100", "fps = 100"}, {"0.5", "fps = 0.5"}, {"1500.25", "fps = 1500.25"},
           {"-2", "fps = -2"}, {"0.000001", "fps = 1e-06"}, {"0.1", "fps = 0.1"}}) {
    Sample s;
    OptionSet set;
    Bind(&set, &s);
    ASSERT_TRUE(set.Parse({"--fps", given}).ok());
    const std::string ini = set.ToIni();
    EXPECT_NE(ini.find(written + "\n"), std::string::npos) << given << " gave:\n" << ini;
    Sample t;
    OptionSet reread;
    Bind(&reread, &t);
    const fs::path file = fs::temp_directory_path() / "hf_options_numbers.ini";
    ASSERT_TRUE(WriteFileAtomic(file, ini).ok());
    ASSERT_TRUE(reread.Parse({"--config", file.string()}).ok());
    EXPECT_EQ(t.fps, s.fps) << given;
    fs::remove(file);
  }
}

TEST(OptionSet, SemanticIniExcludesRuntimeOptionsAndFiltersSection) {
  Sample s;
  OptionSet set;
  Bind(&set, &s);
  const std::string all = set.ToIni();
  const std::string semantic = set.ToIni("ingest", /*semantic_only=*/true);
  EXPECT_NE(all.find("threads"), std::string::npos);
  EXPECT_EQ(semantic.find("threads"), std::string::npos);
  EXPECT_NE(semantic.find("fps = 0"), std::string::npos);
}

TEST(OptionSet, HelpListsEveryOptionWithDefault) {
  Sample s;
  OptionSet set;
  Bind(&set, &s);
  const std::string help = set.Help("headforge ingest [options]", "Ingests.");
  for (const char* text : {"--fps, --ingest.fps", "--max-frames, --ingest.max_frames",
                           "default: 10", "--ingest.name", "--threads", "--config"})
    EXPECT_NE(help.find(text), std::string::npos) << text;
  // Options of several sections come under a heading each, in order.
  const size_t general = help.find("\nGeneral options:\n"), ingest = help.find("\ningest options:\n");
  ASSERT_NE(general, std::string::npos) << help;
  ASSERT_NE(ingest, std::string::npos) << help;
  EXPECT_LT(general, ingest);
  EXPECT_LT(help.find("--threads"), ingest);
  EXPECT_LT(help.find("--help"), ingest);
  EXPECT_GT(help.find("--ingest.fps"), ingest);
  int only = 1;
  OptionSet single;  // --config and --threads: no section, no heading
  single.Add("threads", &only, "Threads.");
  EXPECT_EQ(single.Help("headforge version", "Says.").find(" options:\n"), std::string::npos);
}

TEST(OptionSet, TakenShortFlagFallsBackToDottedKey) {
  double a = 1, b = 2;
  OptionSet set;
  set.Add("ingest.resolution", &a, "a", "resolution");
  set.Add("train.resolution", &b, "b", "resolution");
  ASSERT_TRUE(set.Parse({"--resolution", "3", "--train.resolution", "4"}).ok());
  EXPECT_EQ(a, 3);
  EXPECT_EQ(b, 4);
}

TEST(OptionSet, AnOldFlagNameStillSetsItsOptionWithANote) {
  double size = 1, train = 2, other = 3;
  OptionSet set;
  set.Add("ingest.resolution", &size, "a", "frame-size");
  set.AddOldFlag("ingest.resolution", "resolution");
  set.Add("train.resolution", &train, "b", "train-size");
  set.AddOldFlag("train.resolution", "resolution");  // taken by ingest's: not kept
  set.Add("render.size", &other, "c", "size");
  set.AddOldFlag("render.size", "frame-size");  // another option's present name: not kept
  ASSERT_TRUE(set.Parse({"--resolution", "7", "--train-size", "8"}).ok());
  EXPECT_EQ(size, 7);
  EXPECT_EQ(train, 8);
  ASSERT_EQ(set.deprecation_notes().size(), 1u);
  EXPECT_EQ(set.deprecation_notes()[0], "--resolution is the old name of --frame-size; it still works, but use the new name");
  EXPECT_TRUE(set.WasGiven("ingest.resolution"));
  ASSERT_TRUE(set.Parse({"--frame-size", "5"}).ok());
  EXPECT_EQ(size, 5);
  EXPECT_TRUE(set.deprecation_notes().empty());
  EXPECT_NE(set.Help("u", "d").find("--frame-size, --ingest.resolution <number> (formerly --resolution)"),
            std::string::npos);
  ASSERT_TRUE(set.Parse({"--size", "1"}).ok());
  EXPECT_EQ(other, 1);
}

TEST(FrameList, AllNumbersRangesAndSteps) {
  std::vector<int> frames;
  ASSERT_TRUE(ParseFrameList({"all"}, 4, &frames).ok());
  EXPECT_EQ(frames, (std::vector<int>{0, 1, 2, 3}));
  ASSERT_TRUE(ParseFrameList({"7,2-4", "10-20:5"}, 30, &frames).ok());
  EXPECT_EQ(frames, (std::vector<int>{7, 2, 3, 4, 10, 15, 20}));
  ASSERT_TRUE(ParseFrameList({"0-9:4"}, 10, &frames).ok());
  EXPECT_EQ(frames, (std::vector<int>{0, 4, 8}));
  ASSERT_TRUE(ParseFrameList({"all"}, 0, &frames).ok());
  EXPECT_TRUE(frames.empty());
  // Refused, naming the item; the list given keeps its old value.
  frames = {5};
  for (const char* bad : {"x", "-3", "3-", "4-2", "1-5:0", "1-5:x", "2:3", "1.5", "99999999999"}) {
    const Status s = ParseFrameList({bad}, 100, &frames);
    EXPECT_EQ(s.code(), Status::Code::kInvalidArgument) << bad;
    EXPECT_NE(s.message().find(std::string("'") + bad + "'"), std::string::npos) << s.message();
  }
  const Status past = ParseFrameList({"3,120"}, 100, &frames);
  EXPECT_NE(past.message().find("the frames run 0-99"), std::string::npos) << past.message();
  EXPECT_EQ(frames, (std::vector<int>{5}));
}

}  // namespace
}  // namespace headforge
