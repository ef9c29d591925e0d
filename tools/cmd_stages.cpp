// SPDX-License-Identifier: MIT
// The stage subcommands of aneuprep (phantom … condense, tubewall), one per entry of the stage table; their
// options come from the stages' specs (aneu/pipeline/stage_registry.hpp).
#include <memory>

#include "aneu/core/provenance.hpp"
#include "aneu/pipeline/stage_registry.hpp"
#include "cli_common.hpp"
#include "commands.hpp"

namespace aneu::tools {

namespace {

/// Registers aneuprep's subcommand for stage `name`: its positional input, -o, and one command-line option per
/// option of the stage's spec (key, help, unit, default), so the command line, a case config and
/// `aneuprep run --set` accept exactly the same options, parsed by the same code.
CLI::App* stage_command(CLI::App& app, const std::vector<std::string>& args, std::function<int()>& action, const std::string& name) {
    std::shared_ptr<pipeline::StageJob> job = pipeline::make_stage_job(name);
    const auto& info = job->info();
    struct Io {
        std::string input, output;
    };
    auto io = std::make_shared<Io>();
    auto* c = app.add_subcommand(name, info.help);
    if (info.has_input) c->add_option("input", io->input, info.input_help)->required();
    c->add_option("-o,--output", io->output, info.output_help)->required();
    // Each option lands as text and goes through the spec (as a config value or --set would).
    struct Bound {
        opt::Option o;
        CLI::Option* cli = nullptr;
        std::string text;
        std::vector<std::string> list;
        bool flag = false;
    };
    auto bound = std::make_shared<std::vector<Bound>>(job->options().size());
    const auto options = job->options();
    for (size_t i = 0; i < options.size(); ++i) {
        auto& b = (*bound)[i];
        b.o = options[i];
        const std::string help = b.o.help_text();
        const std::string flag = "--" + b.o.key;
        switch (b.o.form) {
            case opt::Form::VALUE:
                b.cli = c->add_option(flag, b.text, help)->default_str(b.o.default_text);
                break;
            case opt::Form::FLAG:
                b.cli = c->add_flag(b.o.negatable ? flag + ",!--no-" + b.o.key : flag, b.flag, b.o.negatable ? help + " (default: " + b.o.default_text + ")" : help);
                break;
            case opt::Form::NUMBERS:
                b.cli = c->add_option(flag, b.list, help)->delimiter(',')->expected(b.o.count)->default_str(b.o.default_text);
                break;
            case opt::Form::REPEATED:
                b.cli = c->add_option(flag, b.list, help + " (repeatable)");
                break;
            case opt::Form::CHOICES:
                b.cli = c->add_option(flag, b.list, help)->delimiter(',')->default_str(b.o.default_text);
                break;
        }
        if (b.o.form != opt::Form::FLAG) b.cli->type_name(b.o.type_name);
    }
    c->callback([io, job, bound, &action, args, name] {
        action = [io, job, bound, args, name] {
            return run_guarded("aneuprep " + name, [&] {
                for (auto& b : *bound) {
                    if (b.cli->count() == 0) continue;
                    if (b.o.form == opt::Form::FLAG) {
                        job->set(b.o.key, {b.flag ? "true" : "false"});
                    } else if (b.o.form == opt::Form::VALUE) {
                        job->set(b.o.key, {b.text});
                    } else {
                        job->set(b.o.key, b.list);
                    }
                }
                job->validate();
                std::vector<std::string> inputs;
                if (job->info().has_input) inputs.push_back(io->input);
                const auto params = job->parameters();
                Reporter rep = make_log_reporter();
                job->run(io->input, io->output, make_stage_record(name, shell_join(args), params, inputs), rep);
            });
        };
    });
    return c;
}

}  // namespace

void add_stage_commands(CLI::App& app, const std::vector<std::string>& args, std::function<int()>& action) {
    for (const auto& s : pipeline::stage_infos()) stage_command(app, args, action, s.name);
}

}  // namespace aneu::tools
