// SIGINT and SIGTERM: `loom render`, `loom view --record` and `loom bench` stopped at many moments of a run leave no
// partial file, end by the signal (a shell's 128 + N), and keep what they finished whole: every image readable, the
// --stats file listing exactly the frames whose images are written, the video holding whole frames. A second signal
// ends the process at once, still without a partial file. The partial-file registry is also checked alone.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <nlohmann/json.hpp>
#include <regex>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "TestUtil.h"
#include "loom/Display.h"
#include "loom/ImageIO.h"
#include "loom/PartialFiles.h"

namespace fs = std::filesystem;

namespace {

const std::string kTestPattern = std::string(LOOM_TEST_SOURCE_DIR) + "/graphs/TestPattern.json";
constexpr auto kPatience = std::chrono::seconds(20);  // a bound for a hung run, never reached by a working one

/// `loom ARGS` started in `dir` (output to dir/log.txt), with SIGINT and SIGTERM at their defaults whatever the test
/// runner set.
pid_t spawnLoom(const fs::path& dir, const std::vector<std::string>& args) {
    std::vector<std::string> all = {LOOM_TEST_LOOM_EXE};
    all.insert(all.end(), args.begin(), args.end());
    std::vector<char*> argv;
    for (std::string& a : all) argv.push_back(a.data());
    argv.push_back(nullptr);
    const std::string cwd = dir.string(), log = (dir / "log.txt").string();
    const pid_t pid = ::fork();
    if (pid == 0) {  // only async-signal-safe calls until exec: the test process may have threads
        if (::chdir(cwd.c_str()) != 0) ::_exit(126);
        const int out = ::open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
        const int in = ::open("/dev/null", O_RDONLY);
        if (out < 0 || in < 0) ::_exit(126);
        ::dup2(in, 0);
        ::dup2(out, 1);
        ::dup2(out, 2);
        ::signal(SIGINT, SIG_DFL);
        ::signal(SIGTERM, SIG_DFL);
        sigset_t none;
        sigemptyset(&none);
        ::sigprocmask(SIG_SETMASK, &none, nullptr);
        ::execv(argv[0], argv.data());
        ::_exit(127);
    }
    return pid;
}

/// Polls `ready` every millisecond until it holds (true) or kPatience passes (false).
bool waitFor(const std::function<bool()>& ready) {
    const auto end = std::chrono::steady_clock::now() + kPatience;
    while (!ready()) {
        if (std::chrono::steady_clock::now() > end) return false;
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    return true;
}

/// What waitExit() returns for a process that `signal` ended.
constexpr int endedBy(int signal) {
    return -1 - signal;
}

/// The exit code of `pid` (endedBy(signal) if a signal ended it; -1000 if it did not end within kPatience: killed).
int waitExit(pid_t pid) {
    int status = 0;
    const bool ended = waitFor([&] { return ::waitpid(pid, &status, WNOHANG) == pid; });
    if (!ended) {
        ::kill(pid, SIGKILL);
        ::waitpid(pid, &status, 0);
        return -1000;
    }
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1 - WTERMSIG(status);
}

/// Two signals that reach `pid` together: it is stopped, both are sent, then it goes on. SIGINT and SIGTERM, as two
/// of one kind would merge into one while pending. The handler of the first asks to stop, the second ends the process
/// at once (on the same thread right after, or on another thread at the same time), wherever it was stopped: in the
/// middle of writing a file, often.
void twoSignals(pid_t pid) {
    ::kill(pid, SIGSTOP);
    int status = 0;
    ::waitpid(pid, &status, WUNTRACED);  // stopped for sure
    ::kill(pid, SIGINT);
    ::kill(pid, SIGTERM);
    ::kill(pid, SIGCONT);
}

/// Files under `dir` (all depths) whose name contains ".partial".
std::vector<std::string> partialFiles(const fs::path& dir) {
    std::vector<std::string> found;
    std::error_code ec;
    for (auto it = fs::recursive_directory_iterator(dir, ec); !ec && it != fs::recursive_directory_iterator();
         it.increment(ec))
        if (it->path().filename().string().find(".partial") != std::string::npos) found.push_back(it->path().string());
    return found;
}

/// Images (.png, .exr, hidden ones excepted) directly in `dir`.
std::vector<fs::path> images(const fs::path& dir) {
    std::vector<fs::path> found;
    std::error_code ec;
    for (auto it = fs::directory_iterator(dir, ec); !ec && it != fs::directory_iterator(); it.increment(ec)) {
        const std::string name = it->path().filename().string(), ext = it->path().extension().string();
        if (name[0] != '.' && (ext == ".png" || ext == ".exr")) found.push_back(it->path());
    }
    return found;
}

/// The size of a file, 0 while it does not exist.
size_t fileSize(const fs::path& p) {
    std::error_code ec;
    const auto size = fs::file_size(p, ec);
    return ec ? 0 : size_t(size);
}

std::string text(const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

/// Every image in `dir` reads back at 64x64.
void expectReadable(const fs::path& dir) {
    for (const fs::path& p : images(dir)) {
        try {
            const loom::Texture t = loom::readImage(p);
            EXPECT_EQ(t.width(), 64u) << p;
            EXPECT_EQ(t.height(), 64u) << p;
        } catch (const loom::Error& e) {
            ADD_FAILURE() << p << " is not readable: " << e.what();
        }
    }
}

/// Frames of a YUV4MPEG2 file of 64x64 4:4:4 frames; -1 when it is not whole (a header, then whole frames only).
int y4mFrames(const std::string& bytes) {
    const size_t header = bytes.find('\n');
    if (bytes.rfind("YUV4MPEG2 W64 H64 ", 0) != 0 || header == std::string::npos) return -1;
    const size_t frame = 6 + 64 * 64 * 3;  // "FRAME\n" and three planes
    const size_t body = bytes.size() - header - 1;
    if (body % frame != 0) return -1;
    for (size_t at = header + 1; at < bytes.size(); at += frame)
        if (bytes.compare(at, 6, "FRAME\n") != 0) return -1;
    return int(body / frame);
}

class Signals : public loom::test::TempDirTest {
protected:
    /// A fresh folder for one trial.
    fs::path trialDir(int trial) const {
        const fs::path d = mDir / ("trial" + std::to_string(trial));
        fs::create_directories(d / "out");
        return d;
    }
    /// `loom render` of TestPattern at 64x64, every field dumped every frame, far more frames than a trial lasts.
    static std::vector<std::string> renderArgs() {
        return {"render", "--graph", kTestPattern, "--size", "64x64",   "--frames",   "1000000",
                "--dump", "*",       "--out",      "out",    "--stats", "stats.json", "-q"};
    }
};

/// What a render stopped on a signal must hold: whole images only, for exactly the frames the statistics list, each
/// frame with all of its images (the loop stopped between frames).
void expectStoppedRender(const fs::path& dir, const std::string& signal) {
    ASSERT_TRUE(fs::exists(dir / "stats.json")) << text(dir / "log.txt");
    const nlohmann::json stats = nlohmann::json::parse(text(dir / "stats.json"));  // throws (fails) if not JSON
    const auto& frames = stats.at("frames");
    ASSERT_GE(frames.size(), 1u);
    EXPECT_EQ(stats.at("interrupted").at("signal"), signal);
    EXPECT_EQ(stats.at("interrupted").at("framesDone"), frames.size());
    std::set<uint64_t> listed;
    for (const auto& f : frames) listed.insert(f.at("frame").get<uint64_t>());
    std::map<uint64_t, std::set<std::string>> written;  // frame -> Pass.field
    static const std::regex name(R"(([^.]+\.[^.]+)\.([0-9]{4,})\.(png|exr))");
    for (const fs::path& p : images(dir / "out")) {
        std::smatch m;
        const std::string file = p.filename().string();
        ASSERT_TRUE(std::regex_match(file, m, name)) << file;
        written[std::stoull(m[2])].insert(m[1]);
    }
    std::set<uint64_t> writtenFrames;
    for (const auto& [frame, fields] : written) {
        writtenFrames.insert(frame);
        EXPECT_EQ(fields, written.begin()->second) << "frame " << frame << " has another set of images";
    }
    EXPECT_EQ(writtenFrames, listed) << "the images written are not those of the frames the statistics list";
    EXPECT_TRUE(written.begin()->second.count("Display.dst")) << "the output is missing";
    expectReadable(dir / "out");
}

TEST_F(Signals, RenderStopsAfterTheFrameAndWritesWhatItHas) {
    // Signals at different moments: after the first image, and later, while dumps are written back to back.
    const std::vector<size_t> after = {1, 3, 8, 20, 45};
    for (size_t trial = 0; trial < after.size(); ++trial) {
        SCOPED_TRACE("trial " + std::to_string(trial));
        const int sig = trial % 2 ? SIGTERM : SIGINT;
        const fs::path dir = trialDir(int(trial));
        const pid_t pid = spawnLoom(dir, renderArgs());
        ASSERT_GT(pid, 0);
        const bool started = waitFor([&] { return images(dir / "out").size() >= after[trial]; });
        ::kill(pid, sig);
        const int code = waitExit(pid);
        ASSERT_TRUE(started) << text(dir / "log.txt");
        EXPECT_EQ(code, endedBy(sig)) << text(dir / "log.txt");
        EXPECT_EQ(partialFiles(dir), std::vector<std::string>());
        expectStoppedRender(dir, sig == SIGINT ? "SIGINT" : "SIGTERM");
    }
}

void expectSignalExit(int code, const fs::path& dir) {
    EXPECT_TRUE(code == endedBy(SIGINT) || code == endedBy(SIGTERM)) << code << "\n" << text(dir / "log.txt");
}

TEST_F(Signals, SecondSignalExitsAtOnceWithoutPartialFiles) {
    const std::vector<size_t> after = {1, 4, 12, 30, 60};
    int atOnce = 0;
    for (size_t trial = 0; trial < after.size(); ++trial) {
        SCOPED_TRACE("trial " + std::to_string(trial));
        const fs::path dir = trialDir(int(trial));
        const pid_t pid = spawnLoom(dir, renderArgs());
        ASSERT_GT(pid, 0);
        const bool started = waitFor([&] { return images(dir / "out").size() >= after[trial]; });
        twoSignals(pid);
        const int code = waitExit(pid);
        ASSERT_TRUE(started) << text(dir / "log.txt");
        expectSignalExit(code, dir);
        EXPECT_EQ(partialFiles(dir), std::vector<std::string>());
        expectReadable(dir / "out");
        // Ended at once, the run wrote no statistics. It may also have stopped after its frame and written them,
        // when the second signal's handler ran on another thread a little later.
        if (fs::exists(dir / "stats.json")) {
            const nlohmann::json stats = nlohmann::json::parse(text(dir / "stats.json"));
            EXPECT_TRUE(stats.contains("interrupted"));
        } else {
            ++atOnce;
        }
    }
    EXPECT_GE(atOnce, 1) << "no run ended at once: the second signal was not tested";
}

TEST_F(Signals, ViewRecordFinishesTheVideo) {
    const size_t frame = 6 + 64 * 64 * 3, header = 64;  // the header is shorter than 64 bytes
    const std::vector<size_t> after = {1, 5, 17};
    for (size_t trial = 0; trial < after.size(); ++trial) {
        SCOPED_TRACE("trial " + std::to_string(trial));
        const fs::path dir = trialDir(int(trial));
        const pid_t pid = spawnLoom(dir, {"view", "--headless", "--graph", kTestPattern, "--size", "64x64", "--frames",
                                          "1000000", "--record", "video.y4m", "--screenshot", "last.png"});
        ASSERT_GT(pid, 0);
        const bool started =
            waitFor([&] { return fileSize(dir / "video.y4m.partial") >= header + after[trial] * frame; });
        ::kill(pid, SIGINT);
        const int code = waitExit(pid);
        ASSERT_TRUE(started) << text(dir / "log.txt");
        EXPECT_EQ(code, endedBy(SIGINT)) << text(dir / "log.txt");
        EXPECT_EQ(partialFiles(dir), std::vector<std::string>());
        EXPECT_GE(y4mFrames(text(dir / "video.y4m")), int(after[trial])) << "the video is missing or not whole";
        EXPECT_NO_THROW((void)loom::readImage(dir / "last.png"));
    }
}

TEST_F(Signals, ViewRecordSecondSignalLeavesNoPartialVideo) {
    for (int trial = 0; trial < 3; ++trial) {
        SCOPED_TRACE("trial " + std::to_string(trial));
        const fs::path dir = trialDir(trial);
        const pid_t pid = spawnLoom(dir, {"view", "--headless", "--graph", kTestPattern, "--size", "64x64", "--frames",
                                          "1000000", "--record", "video.y4m"});
        ASSERT_GT(pid, 0);
        const bool started =
            waitFor([&] { return fileSize(dir / "video.y4m.partial") > size_t(1 + 8 * trial) * 12288; });
        twoSignals(pid);
        const int code = waitExit(pid);
        ASSERT_TRUE(started) << text(dir / "log.txt");
        expectSignalExit(code, dir);
        EXPECT_EQ(partialFiles(dir), std::vector<std::string>());
        // Ended at once there is no video; stopped after its frame (the second handler a little later), it is whole.
        if (fs::exists(dir / "video.y4m")) {
            EXPECT_GE(y4mFrames(text(dir / "video.y4m")), 1) << "the video is not whole";
        }
    }
}

TEST_F(Signals, BenchStopsWithoutResultsAndKeepsTheCacheWhole) {
    const fs::path dir = trialDir(0);
    const pid_t pid =
        spawnLoom(dir, {"bench", "--scene", loom::test::dataScene("cornell_dynamic.gltf"), "--size", "64x64",
                        "--frames", "200", "--warmup", "2", "--reference-spp", "32", "--graph", "PathTracerATrous",
                        "--brute-force-spp", "1", "--cache", "cache", "--out", "out"});
    ASSERT_GT(pid, 0);
    const auto cached = [&] {
        size_t n = 0;
        std::error_code ec;
        for (auto it = fs::recursive_directory_iterator(dir / "cache", ec);
             !ec && it != fs::recursive_directory_iterator(); it.increment(ec))
            n += it->path().extension() == ".exr" && it->path().filename().string()[0] != '.';
        return n;
    };
    const bool started = waitFor([&] { return cached() >= 2; });
    ::kill(pid, SIGINT);
    const int code = waitExit(pid);
    ASSERT_TRUE(started) << text(dir / "log.txt");
    EXPECT_EQ(code, endedBy(SIGINT)) << text(dir / "log.txt");
    EXPECT_EQ(partialFiles(dir), std::vector<std::string>());
    EXPECT_FALSE(fs::exists(dir / "out" / "results.json")) << "a stopped bench wrote results";
    for (auto it = fs::recursive_directory_iterator(dir / "cache"); it != fs::recursive_directory_iterator(); ++it)
        if (it->path().extension() == ".exr") {
            EXPECT_NO_THROW((void)loom::readImage(it->path())) << it->path();
        }
}

// The registry alone: files registered in a child process that then calls removePartialFiles() (as the signal
// handler does) are gone; files whose registration ended are kept; the Y4M writer's partial video is registered.
TEST_F(Signals, RemovePartialFilesRemovesWhatIsRegistered) {
    const fs::path kept = mDir / "kept.partial", open = mDir / "open.partial", video = mDir / "video.y4m";
    const pid_t pid = ::fork();
    if (pid == 0) {
        int code = 0;
        try {
            {
                loom::PartialFile done(kept.string());
                std::ofstream(kept) << "x";
            }  // renamed, say: its owner's now
            loom::PartialFile registered(open.string());
            std::ofstream(open) << "x";
            registered.created();
            loom::cli::Y4mWriter writer(video, 64, 64, 30.0);
            writer.add(std::vector<uint8_t>(64 * 64 * 4, 128));
            code = loom::partialFileCount() == 2 ? 0 : 3;
            loom::removePartialFiles();
        } catch (...) {
            code = 4;
        }
        ::_exit(code);
    }
    ASSERT_GT(pid, 0);
    EXPECT_EQ(waitExit(pid), 0);
    EXPECT_TRUE(fs::exists(kept));
    EXPECT_FALSE(fs::exists(open));
    EXPECT_FALSE(fs::exists(mDir / "video.y4m.partial"));
    EXPECT_FALSE(fs::exists(video));
}

}  // namespace
