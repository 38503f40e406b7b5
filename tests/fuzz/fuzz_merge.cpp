// In-process fuzzing of `loom image merge` (loom/ShardMerge.h) and `loom image compare`'s comparison. Each
// iteration writes two to four shard folders of partial accumulations, as `loom render --hold` writes them, then
// damages them: header attributes set to strings of every kind (empty, signs, spaces, hex, 23-digit and 2^64-1
// numbers, stray bytes, range lists that overlap, run backwards, join or hold huge numbers) or removed; sums set to
// NaN, Inf, 1e300, DBL_MAX, denormals, -0 or random bits; counts set to 0, 2^32-1 or random; files of another
// size or format, missing files, partials of another frame; shards whose iterations overlap; output folders that
// are a shard, lie in one, hold one, exist with files, exist empty or lie under folders that do not exist yet; and
// a write that fails part way (the checkpoint throws). The contract checked on every input:
//   - mergeShards returns, or throws a loom::Error of the bad-input kind (the injected write failure aside);
//   - on success every output is finite, the counts and iterations are the sums of the inputs', and the headers
//     read back;
//   - on any failure the output path is as it was (absent, or the same folder with the same files), and no staging
//     folder or created parent folder is left;
//   - compareImages finds each output identical to itself and a copy with one changed bit different.
// Seeded: the same --seed and --iterations give the same inputs.
//
// Usage: loom_fuzz_merge [--seed N] [--iterations N] [--work DIR]
// Exit code 0 when every input kept the contract, 1 when any did not (each finding is printed).
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <random>
#include <string>
#include <vector>

#include "loom/DoubleTexels.h"
#include "loom/Error.h"
#include "loom/ExrFile.h"
#include "loom/ImageIO.h"
#include "loom/ShardMerge.h"

namespace fs = std::filesystem;

namespace {

using Rng = std::mt19937_64;

size_t pick(Rng& rng, size_t n) {
    return std::uniform_int_distribution<size_t>(0, n - 1)(rng);
}
bool chance(Rng& rng, double p) {
    return std::uniform_real_distribution<double>(0.0, 1.0)(rng) < p;
}

const char* const kKinds[] = {"partialSumRG", "partialSumBA", "partialCount"};
const char* const kAttributes[] = {"loomHeldFrame", "loomSeedOffset", "loomIterations", "loomSampleRanges",
                                   "loomShards"};

/// One file of a shard as it will be written.
struct File {
    loom::Texture image;
    std::map<std::string, std::string> attributes;
    bool present = true;
};

/// A shard folder: its files by name.
using Shard = std::map<std::string, File>;

std::string digits(Rng& rng, size_t n) {
    std::string s;
    for (size_t i = 0; i < n; ++i) s += char('0' + pick(rng, 10));
    return s;
}

/// A number as a header might hold it: small, huge, at and past 2^64 - 1, 23 digits.
std::string numberText(Rng& rng) {
    switch (pick(rng, 8)) {
        case 0:
            return std::to_string(pick(rng, 10));
        case 1:
            return "18446744073709551615";
        case 2:
            return "18446744073709551614";
        case 3:
            return "18446744073709551616";
        case 4:
            return digits(rng, 23);
        case 5:
            return std::to_string(uint64_t(1) << pick(rng, 64));
        case 6:
            return digits(rng, 1 + pick(rng, 20));
        default:
            return std::to_string(rng() % 100000);
    }
}

/// A range list: mostly well formed, often overlapping, backwards, adjacent, or with odd separators.
std::string rangeList(Rng& rng) {
    std::string s;
    const size_t n = pick(rng, 5);
    for (size_t i = 0; i < n; ++i) {
        if (i) s += chance(rng, 0.9) ? "," : std::string(1, ",-; "[pick(rng, 4)]);
        s += numberText(rng);
        if (chance(rng, 0.7)) s += (chance(rng, 0.95) ? "-" : "--") + numberText(rng);
    }
    if (chance(rng, 0.1)) s += ",";
    return s;
}

std::string attributeText(Rng& rng) {
    switch (pick(rng, 10)) {
        case 0:
            return "";
        case 1:
            return "-" + numberText(rng);
        case 2:
            return "+" + numberText(rng);
        case 3:
            return " " + numberText(rng);
        case 4:
            return "0x" + digits(rng, 4);
        case 5: {
            std::string s(1 + pick(rng, 12), '\0');
            for (char& c : s) c = char(rng());
            return s;
        }
        case 6:
        case 7:
            return rangeList(rng);
        default:
            return numberText(rng);
    }
}

const double kSpecial[] = {std::numeric_limits<double>::quiet_NaN(),
                           std::numeric_limits<double>::infinity(),
                           -std::numeric_limits<double>::infinity(),
                           1e300,
                           -1e300,
                           std::numeric_limits<double>::max(),
                           std::numeric_limits<double>::denorm_min(),
                           -0.0,
                           3.4e38,
                           1e39};

/// Shards of iterations [offset, offset + n) each, with finite sums and counts that agree.
std::vector<Shard> makeShards(Rng& rng, uint32_t w, uint32_t h) {
    std::vector<Shard> shards(2 + pick(rng, 3));
    uint64_t offset = chance(rng, 0.1) ? std::numeric_limits<uint64_t>::max() - 100 : pick(rng, 50);
    for (Shard& shard : shards) {
        const uint64_t n = 1 + pick(rng, 4);
        const std::map<std::string, std::string> a = {
            {"loomHeldFrame", "3"}, {"loomSeedOffset", std::to_string(offset)}, {"loomIterations", std::to_string(n)}};
        File rg{loom::Texture(w, h, loom::Format::RGBA32U), a}, ba{loom::Texture(w, h, loom::Format::RGBA32U), a},
            count{loom::Texture(w, h, loom::Format::R32U), a};
        for (uint32_t y = 0; y < h; ++y)
            for (uint32_t x = 0; x < w; ++x) {
                const uint32_t c = uint32_t(pick(rng, n + 1));
                glm::dvec4 sum(0.0);
                for (uint32_t k = 0; k < c; ++k)
                    sum += glm::dvec4(std::uniform_real_distribution<float>(-2.f, 100.f)(rng));
                loom::packDoubleSum(sum, rg.image.view<glm::uvec4>().at(x, y), ba.image.view<glm::uvec4>().at(x, y));
                count.image.view<uint32_t>().at(x, y) = c;
            }
        shard["Accumulate.partialSumRG.0003.exr"] = std::move(rg);
        shard["Accumulate.partialSumBA.0003.exr"] = std::move(ba);
        shard["Accumulate.partialCount.0003.exr"] = std::move(count);
        offset += n + (chance(rng, 0.3) ? pick(rng, 5) : 0);
        if (chance(rng, 0.05)) offset -= std::min<uint64_t>(offset, 1 + pick(rng, 3));  // overlap
    }
    return shards;
}

File& anyFile(Rng& rng, std::vector<Shard>& shards) {
    Shard& s = shards[pick(rng, shards.size())];
    auto it = s.begin();
    std::advance(it, pick(rng, s.size()));
    return it->second;
}

/// One to three kinds of damage.
void damage(Rng& rng, std::vector<Shard>& shards, uint32_t w, uint32_t h) {
    const size_t n = pick(rng, 4);
    for (size_t k = 0; k < n; ++k) {
        switch (pick(rng, 8)) {
            case 0:
            case 1: {  // a header attribute, in one file or in all three of a shard
                const std::string name = kAttributes[pick(rng, std::size(kAttributes))];
                const std::string value = attributeText(rng);
                const bool remove = chance(rng, 0.1);
                if (chance(rng, 0.5)) {
                    for (auto& [_, f] : shards[pick(rng, shards.size())])
                        remove ? void(f.attributes.erase(name)) : void(f.attributes[name] = value);
                } else {
                    File& f = anyFile(rng, shards);
                    remove ? void(f.attributes.erase(name)) : void(f.attributes[name] = value);
                }
                break;
            }
            case 2:
            case 3: {  // sums
                File& f = shards[pick(rng, shards.size())].at(std::string("Accumulate.") + kKinds[pick(rng, 2)] +
                                                              ".0003.exr");
                if (f.image.format() != loom::Format::RGBA32U) break;
                const auto v = f.image.view<glm::uvec4>();
                glm::uvec4& t = v.at(uint32_t(pick(rng, v.width)), uint32_t(pick(rng, v.height)));
                const double d = chance(rng, 0.8) ? kSpecial[pick(rng, std::size(kSpecial))]
                                                  : loom::wordsToDouble(uint32_t(rng()), uint32_t(rng()));
                const glm::uvec2 words = loom::doubleToWords(d);
                if (chance(rng, 0.5))
                    t.x = words.x, t.y = words.y;
                else
                    t.z = words.x, t.w = words.y;
                break;
            }
            case 4: {  // counts
                File& f = shards[pick(rng, shards.size())].at("Accumulate.partialCount.0003.exr");
                if (f.image.format() != loom::Format::R32U) break;
                const uint32_t values[] = {0u, 0xFFFFFFFFu, 0x80000000u, uint32_t(rng())};
                const auto v = f.image.view<uint32_t>();  // the file may have another size by now
                v.at(uint32_t(pick(rng, v.width)), uint32_t(pick(rng, v.height))) = values[pick(rng, 4)];
                break;
            }
            case 5: {  // another size or format
                File& f = anyFile(rng, shards);
                const loom::Format formats[] = {loom::Format::RGBA32U, loom::Format::R32U, loom::Format::RGBA32F,
                                                loom::Format::RGBA16F, loom::Format::RG32U};
                const loom::Format format = formats[pick(rng, std::size(formats))];
                f.image = loom::Texture(std::max<uint32_t>(1, w + uint32_t(pick(rng, 3)) - 1),
                                        std::max<uint32_t>(1, h + uint32_t(pick(rng, 3)) - 1), format);
                break;
            }
            case 6:  // a missing file
                anyFile(rng, shards).present = false;
                break;
            default: {  // partials of another frame
                Shard& s = shards[pick(rng, shards.size())];
                for (const char* kind : kKinds) {
                    const std::string from = std::string("Accumulate.") + kind + ".0003.exr";
                    File copy{loom::Texture(w, h, s.at(from).image.format()), s.at(from).attributes, true};
                    s[std::string("Accumulate.") + kind + ".0004.exr"] = std::move(copy);
                    if (chance(rng, 0.5)) s.at(from).present = false;
                }
            }
        }
    }
}

void write(const fs::path& dir, const std::vector<Shard>& shards) {
    for (size_t i = 0; i < shards.size(); ++i) {
        fs::create_directories(dir / ("s" + std::to_string(i)));
        for (const auto& [name, f] : shards[i])
            if (f.present) loom::writeImage(dir / ("s" + std::to_string(i)) / name, f.image, f.attributes);
    }
}

/// Everything under a folder (names and sizes), to tell whether a failed merge changed it.
std::vector<std::string> listing(const fs::path& dir) {
    std::vector<std::string> out;
    std::error_code ec;
    if (!fs::exists(dir, ec)) return out;
    if (!fs::is_directory(dir, ec)) return {"file " + std::to_string(fs::file_size(dir, ec))};
    for (fs::recursive_directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec))
        out.push_back(it->path().lexically_relative(dir).string() + " " +
                      (it->is_regular_file() ? std::to_string(it->file_size()) : std::string("dir")));
    std::sort(out.begin(), out.end());
    return out;
}

struct InjectedFailure {};

/// Checks one input; returns what broke the contract ("" when nothing did).
std::string runOne(Rng& rng, const fs::path& work) {
    const uint32_t w = 1 + uint32_t(pick(rng, 4)), h = 1 + uint32_t(pick(rng, 3));
    std::vector<Shard> shards = makeShards(rng, w, h);
    if (chance(rng, 0.85)) damage(rng, shards, w, h);
    write(work, shards);
    std::vector<fs::path> dirs;
    for (size_t i = 0; i < shards.size(); ++i) dirs.push_back(work / ("s" + std::to_string(i)));
    if (chance(rng, 0.05)) dirs.push_back(dirs[pick(rng, dirs.size())]);  // a shard given twice
    if (chance(rng, 0.03)) dirs.push_back(work / "nowhere");

    fs::path out = work / "out";
    switch (pick(rng, 12)) {
        case 0:
            out = dirs[pick(rng, dirs.size())];
            break;
        case 1:
            out = dirs[0] / "inside";
            break;
        case 2:
            out = work;
            break;
        case 3:
            fs::create_directories(out);
            std::ofstream(out / "old.txt") << "old";
            break;
        case 4:
            fs::create_directories(out);
            break;
        case 5:
            std::ofstream(out) << "a file";
            break;
        case 6:
            out = work / "new" / "deeper" / "out";
            break;
        case 7:
            out = work / "." / "s0" / "..";
            break;
        default:
            break;
    }
    const std::vector<std::string> before = listing(work);
    const std::vector<std::string> outBefore = listing(out);
    const bool outExisted = fs::exists(out);
    int failAt = chance(rng, 0.1) ? int(1 + pick(rng, 5)) : 0, calls = 0;
    const auto checkpoint = [&] {
        if (++calls == failAt) throw InjectedFailure{};
    };
    std::vector<loom::MergedFrame> frames;
    bool failed = false;
    try {
        frames = loom::mergeShards(dirs, out, checkpoint);
    } catch (const loom::Error& e) {
        if (e.kind() != loom::ErrorKind::BadInput) return std::string("a runtime error: ") + e.what();
        if (std::string(e.what()).empty()) return "an error without a message";
        failed = true;
    } catch (const InjectedFailure&) {
        failed = true;
    } catch (const std::exception& e) {
        return std::string("an exception that is not a loom::Error: ") + e.what();
    }
    if (failed) {
        if (listing(work) != before) return "a failed merge changed the work folder (left or removed something)";
        if (fs::exists(out) != outExisted || listing(out) != outBefore) return "a failed merge changed its output";
        return "";
    }
    if (failAt > 0 && calls >= failAt) return "the checkpoint threw, yet the merge returned";
    // Success: finite outputs whose counts and iterations add up.
    for (const loom::MergedFrame& f : frames) {
        const fs::path dir = f.mean.parent_path();
        const std::string tail = "." + f.frame + ".exr";
        uint64_t inputIterations = 0;  // of the shards, each once (a shard given twice holds no iterations)
        for (size_t i = 0; i < shards.size(); ++i) {
            const fs::path count = dirs[i] / (f.pass + ".partialCount" + tail);
            inputIterations += loom::iterationCount(loom::readShardHeader(count).iterations).value_or(0);
        }
        const loom::Texture mean = loom::readImage(f.mean);
        const loom::Texture count = loom::readImage(dir / (f.pass + ".partialCount" + tail));
        const loom::Texture rg = loom::readImage(dir / (f.pass + ".partialSumRG" + tail));
        const loom::Texture ba = loom::readImage(dir / (f.pass + ".partialSumBA" + tail));
        for (uint32_t y = 0; y < mean.height(); ++y)
            for (uint32_t x = 0; x < mean.width(); ++x) {
                const glm::vec4 m = mean.view<glm::vec4>().at(x, y);
                const glm::dvec4 s =
                    loom::unpackDoubleSum(rg.view<glm::uvec4>().at(x, y), ba.view<glm::uvec4>().at(x, y));
                for (int c = 0; c < 4; ++c)
                    if (!std::isfinite(m[c]) || !std::isfinite(s[c])) return "a merged value is not finite";
                uint64_t n = 0;
                for (const fs::path& d : dirs)
                    n += loom::readImage(d / (f.pass + ".partialCount" + tail)).view<glm::uvec4>().at(x, y).x;
                if (n != count.view<glm::uvec4>().at(x, y).x) return "a merged count is not the sum of the shards'";
            }
        const loom::ShardHeader merged = loom::readShardHeader(f.mean);
        if (loom::iterationCount(merged.iterations) != f.iterations || f.iterations != inputIterations)
            return "the merged iterations are not the sum of the shards'";
        // compare: identical to itself, different with one bit changed.
        if (loom::compareImages(rg, rg).differ != 0) return "compare finds an image different from itself";
        loom::Texture flipped = loom::readImage(dir / (f.pass + ".partialSumRG" + tail));
        flipped.view<glm::uvec4>().at(uint32_t(pick(rng, flipped.width())),
                                      uint32_t(pick(rng, flipped.height())))[pick(rng, 4)] ^= 1u << pick(rng, 32);
        if (loom::compareImages(rg, flipped).differ != 1) return "compare misses a changed bit";
    }
    for (const auto& e : fs::directory_iterator(work))
        if (e.path().filename().string().find(".merging.") != std::string::npos) return "a staging folder is left";
    return "";
}

}  // namespace

int main(int argc, char** argv) {
    uint64_t seed = 1;
    long iterations = 1000;
    fs::path work;
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        if (i + 1 >= argc) {
            std::fprintf(stderr, "%s needs a value\n", a.c_str());
            return 2;
        }
        const std::string v = argv[++i];
        if (a == "--seed")
            seed = std::stoull(v);
        else if (a == "--iterations")
            iterations = std::stol(v);
        else if (a == "--work")
            work = v;
        else {
            std::fprintf(stderr, "unknown option %s\n", a.c_str());
            return 2;
        }
    }
    spdlog::set_level(spdlog::level::off);
    if (work.empty()) {
        const fs::path shm = "/dev/shm";
        work = (::access(shm.c_str(), W_OK) == 0 ? shm : fs::temp_directory_path()) /
               ("loom_fuzz_merge_" + std::to_string(::getpid()));
    }
    Rng rng(seed);
    long failures = 0, merged = 0;
    const auto start = std::chrono::steady_clock::now();
    for (long it = 0; it < iterations; ++it) {
        std::error_code ec;
        fs::remove_all(work, ec);
        fs::create_directories(work);
        std::string why;
        try {
            why = runOne(rng, work);
        } catch (const std::exception& e) {
            why = std::string("the check itself failed: ") + e.what();
        }
        if (!why.empty()) {
            ++failures;
            std::printf("FAILED iteration %ld: %s\n", it, why.c_str());
        } else if (fs::exists(work / "out" / "Accumulate.mean.0003.exr")) {
            ++merged;
        }
    }
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    std::printf("%ld iterations in %.1f s (%ld merged), %ld failed (seed %llu)\n", iterations, seconds, merged,
                failures, (unsigned long long)seed);
    std::error_code ec;
    fs::remove_all(work, ec);
    return failures ? 1 : 0;
}
