// loom: render graphs headless, check them, list passes, inspect scenes, benchmark run time against error.
#include <spdlog/sinks/stdout_color_sinks.h>
#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cstdio>
#include <functional>
#include <iostream>
#include <map>
#include <set>
#include <sstream>
#include <string>

#include "CliUtil.h"
#include "Interrupt.h"
#include "loom/Error.h"
#include "loom/Log.h"
#include "loom/PartialFiles.h"
#include "loom/Plugin.h"

namespace {

/// A run stopped by SIGINT or SIGTERM, having written what it had, ends by that signal (Interrupt.h says why).
[[noreturn]] void endStopped(int signal) {
    std::cout.flush();
    std::cerr.flush();
    spdlog::default_logger()->flush();
    std::fflush(nullptr);
    loom::cli::endBySignal(signal);
}

/// An option the command does not have may be a pass's parameter (`--device cuda`): says which passes declare it
/// and how to set it, or nothing.
std::string parameterHint(const std::string& message) {
    std::set<std::string> names;
    std::istringstream words(message.substr(std::min(message.find(':'), message.size())));
    for (std::string w; words >> w;)
        if (w.size() > 2 && w.rfind("--", 0) == 0) names.insert(w.substr(2, w.find('=') - 2));
    if (names.empty()) return {};
    try {
        loom::PluginRegistry registry = loom::cli::makeRegistry();
        std::map<std::string, std::vector<std::string>> declaredBy;  // parameter name -> pass types
        for (const std::string& type : registry.knownTypes()) {
            try {  // one plugin that does not load takes no hint away from the others
                const std::unique_ptr<loom::RenderPass> pass = registry.create(type);
                for (const auto& d : pass->params().decls()) declaredBy[d.name].push_back(type);
            } catch (const std::exception&) {
            }
        }
        std::string hint;
        for (const std::string& name : names) {
            const std::vector<std::string>& types = declaredBy[name];
            if (!types.empty())
                hint += fmt::format("'{}' is a parameter of {}, not an option: set it with --set PASS.{}=VALUE (PASS "
                                    "is the pass's name in the graph; `loom check --graph G` lists them); ",
                                    name, loom::join(types), name);
        }
        return hint;
    } catch (const std::exception&) {
        return {};  // a hint, never a second error
    }
}

int run(int argc, char** argv) {
    CLI::App app{"Loom: a frame-graph renderer for path tracing and denoising"};
    app.require_subcommand(1);
    app.set_version_flag("--version", std::string(loom::version()));
    std::string logLevel = "info";
    bool verbose = false;
    app.add_option("--log-level", logLevel, "trace, debug, info, warn, error or off")->capture_default_str();
    app.add_flag("-v,--verbose", verbose, "same as --log-level debug");
    app.parse_complete_callback([&] {
        if (verbose) logLevel = "debug";
        if (!loom::setLogLevel(logLevel))
            loom::throwBadInput("--log-level", "unknown log level '" + logLevel + "'",
                                "trace, debug, info, warn, error or off");
    });
    spdlog::set_pattern("%^[%l]%$ %v");
    spdlog::set_default_logger(spdlog::stderr_color_mt("loom"));
    spdlog::set_pattern("%^[%l]%$ %v");

    loom::cli::addRenderCommand(app);
    loom::cli::addCheckCommand(app);
    loom::cli::addPassesCommand(app);
    loom::cli::addSceneCommand(app);
    loom::cli::addImageCommand(app);
    loom::cli::addBenchCommand(app);
    loom::cli::addViewCommand(app);
    // An unsigned option would take "-1" as 18446744073709551615: every count and size refuses a sign instead.
    const CLI::Validator nonNegative(
        [](std::string& value) {
            const size_t first = value.find_first_not_of(" \t");
            return first != std::string::npos && value[first] == '-'
                       ? value + " is out of range: a count or a size is never negative"
                       : std::string();
        },
        "", "non-negative");
    const std::function<void(CLI::App&)> refuseNegatives = [&](CLI::App& cmd) {
        for (CLI::Option* option : cmd.get_options())
            if (option->get_type_name().rfind("UINT", 0) == 0) option->check(nonNegative);
        for (CLI::App* sub : cmd.get_subcommands({})) refuseNegatives(*sub);
    };
    refuseNegatives(app);
    loom::cli::installSignalHandlers();

    try {
        if (argc > 1 && argv[1][0] != '-') {
            std::vector<std::string> commands;
            for (const CLI::App* sub : app.get_subcommands({})) commands.push_back(sub->get_name());
            if (std::find(commands.begin(), commands.end(), argv[1]) == commands.end())
                loom::throwBadInput(argv[1], std::string("unknown command '") + argv[1] + "'",
                                    "one of: " + loom::join(commands),
                                    loom::didYouMean(argv[1], commands, ""));
        }
        app.parse(argc, argv);
    } catch (const loom::cli::Interrupted& e) {
        std::cerr << "loom: stopped by " << loom::cli::signalName(e.signal)
                  << " before the run's results were written\n";
        endStopped(e.signal);
    } catch (const CLI::CallForHelp& e) {
        return app.exit(e);
    } catch (const CLI::CallForAllHelp& e) {
        return app.exit(e);
    } catch (const CLI::CallForVersion& e) {
        return app.exit(e);
    } catch (const CLI::ExtrasError& e) {
        std::cerr << "error: " << e.what() << "\n  hint: " << parameterHint(e.what())
                  << "run `loom --help` or `loom <command> --help`\n";
        return 2;
    } catch (const CLI::ParseError& e) {
        std::cerr << "error: " << e.what() << "\n  hint: run `loom --help` or `loom <command> --help`\n";
        return 2;
    } catch (const loom::Error& e) {
        std::cerr << "error: " << e.what() << "\n";
        return e.exitCode();
    } catch (const std::exception& e) {
        std::cerr << "error: " << e.what() << "\n";
        return 1;
    } catch (...) {
        std::cerr << "error: an exception that is not a std::exception (thrown by a plugin?)\n";
        return 1;
    }
    if (const int signal = loom::cli::stopSignal()) endStopped(signal);
    return 0;
}

}  // namespace

int main(int argc, char** argv) {
    const int code = run(argc, argv);
    loom::awaitEndIfEnding();  // a second signal's handler on another thread ends the process: its exit, not this
    return code;
}
