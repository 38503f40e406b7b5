#pragma once
// Sample shards of one held frame (`loom render --hold --seed-offset J --frames N` runs of a graph that marks an
// AccumulatePass's partialSumRG, partialSumBA and partialCount) merged into one (`loom image merge`), and images
// compared value for value (`loom image compare`).
//
// A shard's EXR headers say which iterations of the held frame it holds: `loomSampleRanges` lists them as
// inclusive ranges in increasing order ("0-1,4-5", a single iteration as "7", none as ""). A shard written by
// `loom render` holds iterations J to J + N - 1 and says so as `loomSeedOffset` = J and `loomIterations` = N; a
// merged one writes all three (the offset its lowest iteration, the count its total), and a reader takes the
// ranges when present (the other two must then agree with them), else the one range of the offset and count.
#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "loom/Texture.h"

namespace loom {

/// Iterations `first` to `last` of a held frame, both included.
struct IterationRange {
    uint64_t first = 0, last = 0;
    bool operator==(const IterationRange& o) const { return first == o.first && last == o.last; }
};

/// A set of iterations in its one written form: ranges in increasing order, neither overlapping nor adjacent.
using IterationSet = std::vector<IterationRange>;

/// "0-1,4-5" ("7" for a single iteration, "" for none).
std::string formatIterationSet(const IterationSet& set);

/// Reads formatIterationSet's text: decimal numbers below 2^64, ranges in increasing order, none overlapping
/// another (adjacent ones are joined). Throws loom::Error (BadInput, naming `file` and `attribute`) otherwise.
IterationSet parseIterationSet(std::string_view text, const std::string& file, const std::string& attribute);

/// The number of iterations in a set; nothing when it is 2^64 (every iteration), which no uint64 holds.
std::optional<uint64_t> iterationCount(const IterationSet& set);

/// What a shard's header says about its samples.
struct ShardHeader {
    uint64_t heldFrame = 0;
    IterationSet iterations;
};

/// The header of a partial accumulation's EXR (see the top of this file). Throws loom::Error (BadInput, naming the
/// file and the attribute) for a missing, malformed or out-of-range attribute, or ranges that disagree with the
/// offset and count.
ShardHeader readShardHeader(const std::filesystem::path& exr);

/// One pass's frame of a merge: what was merged and where its mean went.
struct MergedFrame {
    std::string pass, frame;  ///< "Accumulate", "0003"
    size_t shards = 0;
    uint64_t iterations = 0;
    std::filesystem::path mean;  ///< <out>/<pass>.mean.<frame>.exr
};

/// Merges the partial accumulations of each (pass, frame) in the shard folders (every shard must hold the same
/// ones) into the new folder `out`: the summed partials (so merges compose), with the union of the shards'
/// iterations in their headers, and their mean <pass>.mean.<frame>.exr as AccumulatePass forms it (double sum /
/// count, rounded to float), so where the double sums are exact the mean equals one run's over all the samples
/// bit for bit. Pixels are summed in the order the shards are given.
///
/// Bad input (loom::Error, BadInput), before anything is written: fewer than two shards; a shard that is no
/// folder; `out` that is a shard, lies inside one or holds one (compared as canonical paths), or exists and is
/// not an empty folder; shards of different frames or sizes; iterations held by two shards; damaged headers;
/// sums that are not finite, counts past 2^32 - 1, or a mean beyond a float's range (an output never holds NaN
/// or Inf). All or nothing: the results are written into a hidden sibling folder that is renamed to `out` at the
/// end; on any failure it is removed, and so are the folders above `out` this call created. `checkpoint`, when
/// set, is called before each file is written and may throw to stop (it is how the command line stops on a
/// signal).
std::vector<MergedFrame> mergeShards(const std::vector<std::filesystem::path>& shards, const std::filesystem::path& out,
                                     const std::function<void()>& checkpoint = {});

/// How two images differ, value by value.
struct ImageComparison {
    bool sameShape = true;        ///< same width, height and format (nothing else is compared otherwise)
    bool integer = false;         ///< integer channels (UINT, 8-bit): compared as integers, exactly
    uint64_t values = 0;          ///< values compared (pixels x channels)
    uint64_t differ = 0;          ///< values whose bits differ (floats, with a tolerance: differ by more than it)
    uint64_t largestInteger = 0;  ///< the largest |a - b| of integer channels
    double largestFloat = 0.0;    ///< the largest |a - b| of float channels; NaN where a NaN met a number
    uint32_t firstX = 0, firstY = 0, firstChannel = 0;  ///< where the first difference is (row by row)
};

/// Compares every channel of every pixel: integers as integers, floats bit for bit, or, with a `tolerance`
/// (absolute, finite and >= 0), as equal when both are NaN or they differ by at most it.
ImageComparison compareImages(const Texture& a, const Texture& b, std::optional<double> tolerance = {});

/// One line saying what compareImages found ("identical: 12 values", "3 of 12 values differ (largest difference
/// 1, first at pixel (0, 0) channel R)").
std::string describeComparison(const Texture& a, const Texture& b, const ImageComparison& c,
                               std::optional<double> tolerance = {});

}  // namespace loom
