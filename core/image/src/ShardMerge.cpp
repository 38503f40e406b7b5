#include "loom/ShardMerge.h"

#include <fmt/format.h>
#include <unistd.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstring>
#include <limits>
#include <map>
#include <regex>
#include <set>

#include "loom/DoubleTexels.h"
#include "loom/Error.h"
#include "loom/ExrFile.h"
#include "loom/ImageIO.h"

namespace loom {

namespace fs = std::filesystem;

namespace {

constexpr uint64_t kMaxU64 = std::numeric_limits<uint64_t>::max();
const char kSampleRanges[] = "loomSampleRanges";
const char kSeedOffset[] = "loomSeedOffset";
const char kIterations[] = "loomIterations";
const char kHeldFrame[] = "loomHeldFrame";
const char kWrittenBy[] = "a partial accumulation written by `loom render --hold` or `loom image merge`";

/// A decimal number below 2^64: digits only, the whole text.
std::optional<uint64_t> parseCount(std::string_view text) {
    if (text.empty() || text.find_first_not_of("0123456789") != std::string_view::npos) return {};
    uint64_t v = 0;
    const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
    if (ec != std::errc() || end != text.data() + text.size()) return {};
    return v;
}

/// Header text as a message shows it: at most 60 characters.
std::string shortText(std::string_view text) {
    return text.size() <= 60 ? std::string(text) : std::string(text.substr(0, 57)) + "...";
}

std::string rangeText(const IterationRange& r) {
    return r.first == r.last ? std::to_string(r.first) : fmt::format("{}-{}", r.first, r.last);
}

uint64_t countAttribute(const ExrFile& f, const char* name) {
    const std::optional<std::string> v = f.stringAttribute(name);
    if (!v) throwBadInput(name, "the header has no such attribute", kWrittenBy, "", f.path().string());
    const std::optional<uint64_t> n = parseCount(*v);
    if (!n)
        throwBadInput(name, "'" + shortText(*v) + "' is not a whole number below 2^64", kWrittenBy, "",
                      f.path().string());
    return *n;
}

/// Folders as lists of names: weakly canonical (symbolic links and "." and ".." resolved), with no empty name for
/// a trailing separator.
std::vector<std::string> pathNames(const fs::path& p) {
    std::error_code ec;
    fs::path c = fs::weakly_canonical(fs::absolute(p, ec), ec);
    if (ec) c = fs::absolute(p).lexically_normal();
    std::vector<std::string> names;
    for (const fs::path& part : c)
        if (!part.empty() && part != "/" && part != ".") names.push_back(part.string());
    return names;
}

bool startsWith(const std::vector<std::string>& path, const std::vector<std::string>& prefix) {
    return prefix.size() <= path.size() && std::equal(prefix.begin(), prefix.end(), path.begin());
}

/// The output folder must be none of the shards, lie in none and hold none, and be new or empty.
void checkOutputFolder(const std::vector<fs::path>& shards, const fs::path& out) {
    if (out.empty()) throwBadInput("--out", "the output folder is an empty path", "a folder to write the merge into");
    const std::vector<std::string> o = pathNames(out);
    for (const fs::path& shard : shards) {
        const std::vector<std::string> s = pathNames(shard);
        const char* how = o == s             ? "is the shard folder"
                          : startsWith(o, s) ? "lies inside the shard folder"
                          : startsWith(s, o) ? "holds the shard folder"
                                             : nullptr;
        if (how)
            throwBadInput(
                "--out",
                fmt::format("'{}' {} '{}': the merge would overwrite what it reads", out.string(), how, shard.string()),
                "an output folder apart from every shard", "choose another --out folder");
    }
    std::error_code ec;
    const fs::file_status st = fs::status(out, ec);
    if (!fs::exists(st)) return;
    if (!fs::is_directory(st))
        throwBadInput("--out", "'" + out.string() + "' exists and is not a folder", "a new or empty folder",
                      "choose another --out folder");
    if (!fs::is_empty(out, ec) || ec)
        throwBadInput("--out",
                      "'" + out.string() +
                          "' exists and holds files: a merge writes a new folder, whole or not at all, and never "
                          "mixes its results with older ones",
                      "a new or empty folder", "remove it or choose another --out folder");
}

/// (pass, frame) of each partial accumulation in a folder (PASS.partialCount.FRAME.exr), sorted.
std::set<std::pair<std::string, std::string>> partialsIn(const fs::path& dir) {
    static const std::regex name(R"((.+)\.partialCount\.([0-9]{4,})\.exr)");
    std::set<std::pair<std::string, std::string>> groups;
    std::error_code ec;
    for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
        std::smatch m;
        const std::string file = it->path().filename().string();
        if (std::regex_match(file, m, name)) groups.emplace(m[1], m[2]);
    }
    if (ec) throwBadInput("", "cannot list the folder: " + ec.message(), "a readable folder", "", dir.string());
    return groups;
}

std::string describeGroups(const std::set<std::pair<std::string, std::string>>& groups) {
    std::vector<std::string> items;
    for (const auto& [pass, frame] : groups) items.push_back(pass + " of frame " + frame);
    if (items.size() > 4) {
        items.resize(4);
        items.back() = "...";
    }
    return items.empty() ? "none" : join(items);
}

/// One shard's partial accumulation of one (pass, frame).
struct Partial {
    fs::path rgPath, baPath, countPath;
    Texture sumRG, sumBA, count;
    ShardHeader header;
    uint64_t samplesAtMost = 0;  ///< the iterations it holds: AccumulatePass adds one sample a pixel per iteration
};

Partial readPartial(const fs::path& dir, const std::string& pass, const std::string& frame) {
    Partial p;
    p.rgPath = dir / (pass + ".partialSumRG." + frame + ".exr");
    p.baPath = dir / (pass + ".partialSumBA." + frame + ".exr");
    p.countPath = dir / (pass + ".partialCount." + frame + ".exr");
    for (const fs::path& f : {p.rgPath, p.baPath, p.countPath}) {
        std::error_code ec;
        if (!fs::is_regular_file(f, ec))
            throwBadInput("",
                          "missing: each shard needs " + pass +
                              "'s partialSumRG, partialSumBA and partialCount of "
                              "frame " +
                              frame,
                          "the outputs of every shard's run", "", f.string());
    }
    p.header = readShardHeader(p.countPath);
    // The three files of a shard come from one run: their headers agree.
    for (const fs::path& f : {p.rgPath, p.baPath}) {
        const ShardHeader h = readShardHeader(f);
        if (h.heldFrame != p.header.heldFrame || h.iterations != p.header.iterations)
            throwBadInput(
                "",
                fmt::format("its header (frame {}, iterations {}) disagrees with {}'s (frame {}, "
                            "iterations {})",
                            h.heldFrame, shortText(formatIterationSet(h.iterations)), p.countPath.filename().string(),
                            p.header.heldFrame, shortText(formatIterationSet(p.header.iterations))),
                "the three partial files of one run", "", f.string());
    }
    p.samplesAtMost = iterationCount(p.header.iterations).value_or(kMaxU64);
    p.sumRG = readImage(p.rgPath);
    p.sumBA = readImage(p.baPath);
    p.count = readImage(p.countPath);
    return p;
}

/// Refuses iterations held by two shards, and returns the union of all.
IterationSet unionOfDisjoint(const std::vector<Partial>& partials, const std::vector<fs::path>& shards) {
    std::vector<std::pair<IterationRange, size_t>> all;
    for (size_t i = 0; i < partials.size(); ++i)
        for (const IterationRange& r : partials[i].header.iterations) all.emplace_back(r, i);
    std::sort(all.begin(), all.end(), [](const auto& a, const auto& b) {
        return a.first.first != b.first.first ? a.first.first < b.first.first : a.second < b.second;
    });
    IterationSet merged;
    size_t owner = 0;  // the shard of merged.back()'s last range
    for (const auto& [r, shard] : all) {
        if (!merged.empty() && r.first <= merged.back().last) {
            const IterationRange both{r.first, std::min(r.last, merged.back().last)};
            const bool same = pathNames(shards[shard]) == pathNames(shards[owner]);
            throwBadInput(
                "",
                fmt::format("its iterations {} are also in '{}'{} (this shard holds {}, that one {})", rangeText(both),
                            shards[owner].string(), same ? ", the same folder given twice" : "",
                            shortText(formatIterationSet(partials[shard].header.iterations)),
                            shortText(formatIterationSet(partials[owner].header.iterations))),
                "shards whose iterations (--seed-offset J --frames N: J to J + N - 1) do not overlap",
                "leave out one of the two", shards[shard].string());
        }
        if (!merged.empty() && merged.back().last != kMaxU64 && r.first == merged.back().last + 1)
            merged.back().last = r.last;
        else
            merged.push_back(r);
        owner = shard;
    }
    return merged;
}

const char* const kChannelNames[] = {"R", "G", "B", "A"};

/// The four sums of a shard's pixel, refused when one is not finite.
glm::dvec4 finiteSum(const Partial& p, uint32_t x, uint32_t y) {
    const glm::uvec4 rg = p.sumRG.view<glm::uvec4>().at(x, y), ba = p.sumBA.view<glm::uvec4>().at(x, y);
    const glm::dvec4 sum = unpackDoubleSum(rg, ba);
    for (int c = 0; c < 4; ++c)
        if (!std::isfinite(sum[c]))
            throwBadInput(fmt::format("pixel ({}, {})", x, y),
                          fmt::format("the sum of {} is {}", kChannelNames[c], sum[c]),
                          "finite sums (AccumulatePass adds only finite samples)", "render this shard again",
                          (c < 2 ? p.rgPath : p.baPath).string());
    return sum;
}

struct MergedImages {
    Texture sumRG, sumBA, count, mean;
};

MergedImages sumPartials(const std::vector<Partial>& partials) {
    const uint32_t w = partials.front().count.width(), h = partials.front().count.height();
    MergedImages m{Texture(w, h, Format::RGBA32U), Texture(w, h, Format::RGBA32U), Texture(w, h, Format::R32U),
                   Texture(w, h, Format::RGBA32F)};
    const auto rg = m.sumRG.view<glm::uvec4>(), ba = m.sumBA.view<glm::uvec4>();
    const auto cv = m.count.view<uint32_t>();
    const auto mv = m.mean.view<glm::vec4>();
    const double floatMax = std::numeric_limits<float>::max();
    for (uint32_t y = 0; y < h; ++y)
        for (uint32_t x = 0; x < w; ++x) {
            glm::dvec4 sum(0.0);
            uint64_t n = 0;
            for (const Partial& p : partials) {  // in the order given: the same bits for the same order
                const glm::dvec4 s = finiteSum(p, x, y);
                const uint32_t c = p.count.view<glm::uvec4>().at(x, y).x;
                if (c > p.samplesAtMost)
                    throwBadInput(fmt::format("pixel ({}, {})", x, y),
                                  fmt::format("{} samples, but the header says the shard holds {} iteration{}", c,
                                              p.samplesAtMost, p.samplesAtMost == 1 ? "" : "s"),
                                  "at most one sample of a pixel per iteration", "render this shard again",
                                  p.countPath.string());
                if (c == 0 && s != glm::dvec4(0.0))
                    throwBadInput(fmt::format("pixel ({}, {})", x, y), "a sum of no samples is not 0",
                                  "a sum of 0 where partialCount is 0", "render this shard again",
                                  p.countPath.string());
                sum += s;
                n += c;
            }
            const std::string where = fmt::format("pixel ({}, {})", x, y);
            if (n > 0xFFFFFFFFull)
                throwBadInput(where, fmt::format("the shards hold {} samples of it together", n),
                              "at most 2^32 - 1 samples in a pixel (partialCount is 32-bit)",
                              "merge fewer shards, or render fewer iterations", partials.front().countPath.string());
            const glm::dvec4 mean = n == 0 ? glm::dvec4(0.0) : sum / double(n);
            for (int c = 0; c < 4; ++c)
                if (!std::isfinite(sum[c]) || !(std::fabs(mean[c]) <= floatMax))
                    throwBadInput(where,
                                  fmt::format("the merged mean of {} ({:g} / {}) is beyond a float's range",
                                              kChannelNames[c], sum[c], n),
                                  "sums whose mean a float holds (at most 3.4e38 in magnitude)",
                                  "render the shards again: no float sample gives such sums",
                                  partials.front().rgPath.string());
            packDoubleSum(sum, rg.at(x, y), ba.at(x, y));
            cv.at(x, y) = uint32_t(n);
            mv.at(x, y) = glm::vec4(mean);
        }
    return m;
}

/// Removes a folder tree on destruction unless released.
struct FolderCleanup {
    std::vector<fs::path> folders;  ///< removed in this order (deepest first)
    bool released = false;
    ~FolderCleanup() {
        if (released) return;
        std::error_code ec;
        for (const fs::path& f : folders) {
            if (&f == &folders.front())
                fs::remove_all(f, ec);
            else
                fs::remove(f, ec);  // only while empty: a folder someone else wrote into stays
        }
    }
};

}  // namespace

std::string formatIterationSet(const IterationSet& set) {
    std::string out;
    for (const IterationRange& r : set) {
        if (!out.empty()) out += ',';
        out += rangeText(r);
    }
    return out;
}

IterationSet parseIterationSet(std::string_view text, const std::string& file, const std::string& attribute) {
    IterationSet set;
    if (text.empty()) return set;
    const std::string expected = "iterations as ranges in increasing order, none overlapping another, e.g. 0-1,4-5";
    size_t at = 0;
    while (at <= text.size()) {
        const size_t comma = std::min(text.find(',', at), text.size());
        const std::string_view item = text.substr(at, comma - at);
        const size_t dash = item.find('-');
        const std::optional<uint64_t> first = parseCount(item.substr(0, dash));
        const std::optional<uint64_t> last = dash == std::string_view::npos ? first : parseCount(item.substr(dash + 1));
        if (!first || !last)
            throwBadInput(attribute,
                          fmt::format("'{}' in '{}' is not a range of whole numbers below 2^64", shortText(item),
                                      shortText(text)),
                          expected, "", file);
        if (*last < *first)
            throwBadInput(attribute, fmt::format("the range '{}' ends before it starts", shortText(item)), expected, "",
                          file);
        if (!set.empty() && *first <= set.back().last)
            throwBadInput(attribute,
                          fmt::format("the range '{}' overlaps or precedes '{}' before it", shortText(item),
                                      rangeText(set.back())),
                          expected, "", file);
        if (!set.empty() && *first == set.back().last + 1)
            set.back().last = *last;
        else
            set.push_back({*first, *last});
        at = comma + 1;
    }
    return set;
}

std::optional<uint64_t> iterationCount(const IterationSet& set) {
    uint64_t total = 0;
    for (const IterationRange& r : set) {
        const uint64_t span = r.last - r.first;  // one less than the count
        if (span == kMaxU64 || total > kMaxU64 - span - 1) return {};
        total += span + 1;
    }
    return total;
}

ShardHeader readShardHeader(const fs::path& exr) {
    const ExrFile f(exr);
    const std::string file = exr.string();
    ShardHeader h;
    h.heldFrame = countAttribute(f, kHeldFrame);
    const uint64_t offset = countAttribute(f, kSeedOffset), iterations = countAttribute(f, kIterations);
    if (const std::optional<std::string> ranges = f.stringAttribute(kSampleRanges)) {
        h.iterations = parseIterationSet(*ranges, file, kSampleRanges);
        const std::optional<uint64_t> count = iterationCount(h.iterations);
        if (!count || *count != iterations)
            throwBadInput(kIterations,
                          fmt::format("{} iterations, but {} holds {}", iterations, kSampleRanges,
                                      count ? std::to_string(*count) : "2^64"),
                          "the count of the iterations loomSampleRanges lists", "", file);
        if (!h.iterations.empty() && h.iterations.front().first != offset)
            throwBadInput(kSeedOffset,
                          fmt::format("{}, but {} starts at {}", offset, kSampleRanges, h.iterations.front().first),
                          "the first iteration loomSampleRanges lists", "", file);
    } else if (iterations > 0) {
        if (iterations - 1 > kMaxU64 - offset)
            throwBadInput(
                kIterations,
                fmt::format("{} iterations from {} {} pass iteration 2^64 - 1", iterations, kSeedOffset, offset),
                "iterations numbered below 2^64", "", file);
        h.iterations.push_back({offset, offset + (iterations - 1)});
    }
    return h;
}

std::vector<MergedFrame> mergeShards(const std::vector<fs::path>& shards, const fs::path& out,
                                     const std::function<void()>& checkpoint) {
    if (shards.size() < 2) throwBadInput("loom image merge", "fewer than two shard folders", "two or more");
    const std::string folderExpected = "folders written by `loom render --hold` (one per shard)";
    for (const fs::path& s : shards) {
        std::error_code ec;
        const fs::file_status st = fs::status(s, ec);
        if (!fs::exists(st)) throwBadInput("", "no such folder", folderExpected, "", s.string());
        if (!fs::is_directory(st)) throwBadInput("", "not a folder", folderExpected, "", s.string());
    }
    checkOutputFolder(shards, out);

    // Every shard holds the same (pass, frame)s: a shard of another frame is named with what it holds.
    const auto groups = partialsIn(shards.front());
    if (groups.empty())
        throwBadInput("", "no partial accumulation (PASS.partialCount.FRAME.exr) in the folder",
                      "the outputs of a graph marking an AccumulatePass's partialSumRG, partialSumBA and partialCount "
                      "(graphs/ReferenceShard.json)",
                      "", shards.front().string());
    for (size_t i = 1; i < shards.size(); ++i) {
        const auto other = partialsIn(shards[i]);
        if (other != groups)
            throwBadInput("",
                          fmt::format("holds partial accumulations of {}; the first shard, '{}', of {}",
                                      describeGroups(other), shards.front().string(), describeGroups(groups)),
                          "shards of the same frames (one --start-frame)", "merge each frame's shards apart",
                          shards[i].string());
    }

    // Everything is read and checked before the first write.
    struct Group {
        MergedFrame info;
        ShardHeader header;
        MergedImages images;
    };
    std::vector<Group> merged;
    for (const auto& [pass, frame] : groups) {
        std::vector<Partial> partials;
        for (const fs::path& dir : shards) partials.push_back(readPartial(dir, pass, frame));
        const Partial& first = partials.front();
        const uint32_t w = first.count.width(), h = first.count.height();
        for (size_t i = 0; i < partials.size(); ++i) {
            const Partial& p = partials[i];
            for (const Texture* t : {&p.sumRG, &p.sumBA, &p.count})
                if (t->width() != w || t->height() != h || t->format() != Format::RGBA32U) {
                    const fs::path& file = t == &p.sumRG ? p.rgPath : t == &p.sumBA ? p.baPath : p.countPath;
                    throwBadInput("",
                                  fmt::format("a {}x{} {} image, the first shard's partialCount is {}x{}", t->width(),
                                              t->height(), formatName(t->format()), w, h),
                                  "UINT images of one size (partials of one frame)", "", file.string());
                }
            if (p.header.heldFrame != first.header.heldFrame)
                throwBadInput("",
                              fmt::format("holds frame {}, the first shard '{}' frame {}", p.header.heldFrame,
                                          shards.front().string(), first.header.heldFrame),
                              "shards of one frame", "merge each frame's shards apart", shards[i].string());
        }
        Group g;
        g.header.heldFrame = first.header.heldFrame;
        g.header.iterations = unionOfDisjoint(partials, shards);
        const std::optional<uint64_t> total = iterationCount(g.header.iterations);
        if (!total)
            throwBadInput("", "the shards hold every one of the 2^64 iterations, more than a count can say",
                          "fewer iterations", "", shards.front().string());
        g.info = {pass, frame, shards.size(), *total, {}};
        g.images = sumPartials(partials);
        merged.push_back(std::move(g));
    }

    // All or nothing: a hidden sibling folder, renamed to `out` once it holds everything.
    fs::path target = fs::weakly_canonical(fs::absolute(out));
    if (target.filename().empty()) target = target.parent_path();
    const fs::path parent = target.parent_path();
    FolderCleanup cleanup;
    const fs::path staging = parent / ("." + target.filename().string() + ".merging." + std::to_string(::getpid()));
    cleanup.folders.push_back(staging);
    for (fs::path p = parent; !p.empty() && !fs::exists(p); p = p.parent_path()) cleanup.folders.push_back(p);
    std::error_code ec;
    fs::create_directories(parent, ec);
    if (!ec) {
        fs::remove_all(staging, ec);
        fs::create_directory(staging, ec);
    }
    if (ec)
        throwBadInput("--out", "cannot create a folder beside '" + out.string() + "': " + ec.message(),
                      "a writable location", "choose another --out folder");
    for (Group& g : merged) {
        const std::string tail = "." + g.info.frame + ".exr";
        const std::map<std::string, std::string> attributes = {
            {kHeldFrame, std::to_string(g.header.heldFrame)},
            {kSampleRanges, formatIterationSet(g.header.iterations)},
            {kSeedOffset, std::to_string(g.header.iterations.empty() ? 0 : g.header.iterations.front().first)},
            {kIterations, std::to_string(g.info.iterations)},
            {"loomShards", std::to_string(shards.size())}};
        const std::pair<const char*, const Texture*> files[] = {{".partialSumRG", &g.images.sumRG},
                                                                {".partialSumBA", &g.images.sumBA},
                                                                {".partialCount", &g.images.count},
                                                                {".mean", &g.images.mean}};
        for (const auto& [kind, tex] : files) {
            if (checkpoint) checkpoint();
            writeImage(staging / (g.info.pass + kind + tail), *tex, attributes);
        }
        g.info.mean = target / (g.info.pass + ".mean" + tail);
    }
    if (checkpoint) checkpoint();
    // rename(2) replaces an empty folder in one step; a folder that gained files since the check is not replaced.
    fs::rename(staging, target, ec);
    if (ec)
        throw Error(Error::Info{ErrorKind::Runtime, out.string(), "",
                                "cannot move the merged results into place: " + ec.message(),
                                "a new or empty output folder", ""});
    cleanup.released = true;
    std::vector<MergedFrame> result;
    for (Group& g : merged) result.push_back(std::move(g.info));
    return result;
}

ImageComparison compareImages(const Texture& a, const Texture& b, std::optional<double> tolerance) {
    ImageComparison c;
    if (a.width() != b.width() || a.height() != b.height() || a.format() != b.format()) {
        c.sameShape = false;
        return c;
    }
    const FormatInfo& info = formatInfo(a.format());
    const size_t size = info.bytesPerPixel / info.channels;  // bytes of one channel
    c.integer = info.component == ComponentType::Uint32 || info.component == ComponentType::Unorm8;
    c.values = uint64_t(a.width()) * a.height() * info.channels;
    const auto load = [size](const std::byte* p) {
        uint32_t v = 0;
        std::memcpy(&v, p, size);  // little-endian: the low bytes
        return v;
    };
    for (uint32_t y = 0; y < a.height(); ++y)
        for (uint32_t x = 0; x < a.width(); ++x)
            for (uint32_t ch = 0; ch < info.channels; ++ch) {
                const size_t at = size_t(x) * info.bytesPerPixel + ch * size;
                const uint32_t u = load(a.row(y) + at), v = load(b.row(y) + at);
                bool differs = u != v;
                if (c.integer) {
                    if (differs) c.largestInteger = std::max(c.largestInteger, uint64_t(u > v ? u - v : v - u));
                } else if (differs) {
                    const double p = a.texel(x, y, ch), q = b.texel(x, y, ch);
                    const bool bothNan = std::isnan(p) && std::isnan(q);
                    const double d = bothNan ? 0.0 : std::fabs(p - q);  // NaN where a NaN met a number
                    if (tolerance) differs = !bothNan && !(d <= *tolerance);
                    if (differs && !std::isnan(c.largestFloat))
                        c.largestFloat = std::isnan(d) ? d : std::max(c.largestFloat, d);
                }
                if (differs && c.differ++ == 0) c.firstX = x, c.firstY = y, c.firstChannel = ch;
            }
    return c;
}

std::string describeComparison(const Texture& a, const Texture& b, const ImageComparison& c,
                               std::optional<double> tolerance) {
    if (!c.sameShape)
        return fmt::format("{}x{} {} vs {}x{} {}", a.width(), a.height(), formatName(a.format()), b.width(), b.height(),
                           formatName(b.format()));
    if (c.differ == 0) {
        if (!tolerance || c.integer || a.samePixels(b)) return fmt::format("identical: {} values", c.values);
        return fmt::format("equal within {:g}: {} values", *tolerance, c.values);
    }
    const std::string largest = c.integer ? std::to_string(c.largestInteger) : fmt::format("{:g}", c.largestFloat);
    return fmt::format("{} of {} values differ{} (largest difference {}, first at pixel ({}, {}) channel {})", c.differ,
                       c.values,
                       tolerance && !c.integer ? fmt::format(" by more than {:g}", *tolerance) : std::string(), largest,
                       c.firstX, c.firstY, kChannelNames[c.firstChannel]);
}

}  // namespace loom
