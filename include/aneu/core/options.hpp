// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// One declaration per stage option (issue #16). A `Spec<P>` lists the options of a parameter struct P: key,
/// form, unit, bound or choices, help text, provenance name. From it come the command-line options (tools/),
/// the TOML keys of a case config and `--set STAGE.KEY=VALUE` (pipeline::run_case), validation with one
/// message per rule, the provenance parameter list and the `--help` text. The struct keeps the defaults
/// (CONVENTIONS.md §5); the spec reads them from a default-constructed P.
///
/// Every value arrives as text (a command-line word, a TOML value, the right side of --set) and goes through
/// `Spec::set`, so the three routes cannot drift apart. Messages: "<stage>: --<key> must be <rule> [unit]
/// (got <value>)" for a bound, "<stage>: --<key> '<text>': expected <what>" for a value that does not parse.
#include <array>
#include <cmath>
#include <functional>
#include <limits>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "aneu/core/error.hpp"
#include "aneu/core/text.hpp"

namespace aneu {

namespace opt {

/// How an option is written on the command line.
enum class Form {
    VALUE,     ///< --key V
    FLAG,      ///< --key / --no-key (TOML: key = true|false)
    NUMBERS,   ///< --key a,b,c (a fixed count of numbers; TOML: key = [a, b, c])
    REPEATED,  ///< --key a,b,c repeatable (TOML: key = ["a,b,c", ...])
    CHOICES,   ///< --key a,b (a list of choices; TOML: key = ["a", "b"])
};

/// A bound on a number, with its rule as text for messages and help ("> 0", "in [0, 100]").
struct Bound {
    double lo = -std::numeric_limits<double>::infinity();
    double hi = std::numeric_limits<double>::infinity();
    bool lo_open = false, hi_open = false;
    std::string rule;
    bool ok(double v) const {
        if (!std::isfinite(v)) return false;
        return (lo_open ? v > lo : v >= lo) && (hi_open ? v < hi : v <= hi);
    }
};
Bound any();
Bound gt(double x);
Bound ge(double x);
Bound open(double a, double b);        ///< (a, b)
Bound closed(double a, double b);      ///< [a, b]
Bound closed_open(double a, double b); ///< [a, b)
Bound open_closed(double a, double b); ///< (a, b]

/// What the help and the tests see of an option.
struct Option {
    std::string key;           ///< command-line --key and TOML key
    std::string name;          ///< its name in provenance
    std::string help;
    std::string unit;          ///< "mm", "HU", "" (shown in help as [unit])
    Form form = Form::VALUE;
    int count = 1;             ///< numbers per value (NUMBERS, REPEATED)
    std::vector<std::string> choices;
    bool provenance = true;    ///< false: an output-side option (a snapshot path), not a parameter of the result
    bool negatable = true;     ///< FLAG: also --no-<key>
    std::string default_text;  ///< the default as provenance shows it
    std::string rule;          ///< the bound as text ("> 0"), "" if none
    std::string type_name = "TEXT";  ///< what the help shows as the value's type
    /// Help line: text, unit, choices and rule.
    std::string help_text() const;
};

/// Parses a number; `what` names the option for the message. @throws InputError
double parse_number(const std::string& text, const std::string& what);
/// Parses an integer. @throws InputError
long long parse_integer(const std::string& text, const std::string& what);
/// Parses true/false/1/0/yes/no/on/off. @throws InputError
bool parse_bool(const std::string& text, const std::string& what);
/// The words of the values split at commas ("a,b" and {"a", "b"} give the same).
std::vector<std::string> split_commas(const std::vector<std::string>& values);
/// Splits the values at commas ("1,2,3" and {"1","2","3"} give the same) and parses `n` numbers.
std::vector<double> parse_numbers(const std::vector<std::string>& values, std::size_t n, const std::string& what);
/// Numbers joined by `sep` in shortest form.
template <class C>
std::string join_numbers(const C& c, const char* sep = ",") {
    std::string s;
    for (double x : c) s += (s.empty() ? "" : sep) + shortest(x);
    return s;
}

/// The options of a parameter struct P, declared once.
template <class P>
class Spec {
public:
    using Setter = std::function<void(P&, const std::vector<std::string>&)>;
    using Shower = std::function<std::string(const P&)>;
    using Checker = std::function<void(const P&)>;
    struct Entry {
        Option option;
        Setter set;
        Shower show;
        Checker check;
    };

    explicit Spec(std::string stage) : m_stage(std::move(stage)) {}
    const std::string& stage() const { return m_stage; }
    const std::vector<Entry>& entries() const { return m_entries; }
    std::vector<Option> options() const {
        std::vector<Option> o;
        for (const auto& e : m_entries) o.push_back(e.option);
        return o;
    }

    /// A real number. `zero_means`: text provenance shows for 0 ("auto", "artery / 3"), "" = the number.
    template <class A>
    Spec& real(std::string key, A field, std::string unit, Bound b, std::string help, std::string zero_means = "") {
        Option o = base(std::move(key), std::move(unit), std::move(help), Form::VALUE);
        const std::string what = flag_name(o.key);
        const std::string stage = m_stage;
        const std::string unit_text = o.unit.empty() ? "" : " " + o.unit;
        o.rule = b.rule;
        o.type_name = "REAL";
        return add(std::move(o),
                   [field, what](P& p, const std::vector<std::string>& v) { ref(p, field) = parse_number(one(v, what), what); },
                   [field, zero_means](const P& p) {
                       const double x = cref(p, field);
                       return x == 0 && !zero_means.empty() ? zero_means : shortest(x);
                   },
                   [field, b, what, stage, unit_text](const P& p) {
                       const double x = cref(p, field);
                       if (!b.ok(x)) throw InputError(stage + ": " + what + " must be " + b.rule + unit_text + " (got " + shortest(x) + ")");
                   });
    }
    /// An integer (int or uint64_t field).
    template <class A>
    Spec& integer(std::string key, A field, Bound b, std::string help) {
        Option o = base(std::move(key), "", std::move(help), Form::VALUE);
        const std::string what = flag_name(o.key);
        const std::string stage = m_stage;
        o.rule = b.rule;
        o.type_name = "INT";
        return add(std::move(o),
                   [field, what](P& p, const std::vector<std::string>& v) {
                       auto& r = ref(p, field);
                       r = static_cast<std::decay_t<decltype(r)>>(parse_integer(one(v, what), what));
                   },
                   [field](const P& p) { return std::to_string(cref(p, field)); },
                   [field, b, what, stage](const P& p) {
                       const double x = static_cast<double>(cref(p, field));
                       if (!b.ok(x)) throw InputError(stage + ": " + what + " must be " + b.rule + " (got " + shortest(x) + ")");
                   });
    }
    /// Text; with `choices`, one of them.
    template <class A>
    Spec& text(std::string key, A field, std::vector<std::string> choices, std::string help, std::string empty_means = "") {
        Option o = base(std::move(key), "", std::move(help), Form::VALUE);
        o.choices = choices;
        const std::string what = flag_name(o.key);
        const std::string stage = m_stage;
        return add(std::move(o), [field, what](P& p, const std::vector<std::string>& v) { ref(p, field) = one(v, what); },
                   [field, empty_means](const P& p) {
                       const std::string& s = cref(p, field);
                       return s.empty() && !empty_means.empty() ? empty_means : s;
                   },
                   [field, choices, what, stage](const P& p) { check_choice(stage, what, cref(p, field), choices); });
    }
    /// A boolean flag (--key and, when negatable, --no-key).
    template <class A>
    Spec& flag(std::string key, A field, std::string help, bool negatable = true) {
        Option o = base(std::move(key), "", std::move(help), Form::FLAG);
        o.negatable = negatable;
        const std::string what = flag_name(o.key);
        return add(std::move(o), [field, what](P& p, const std::vector<std::string>& v) { ref(p, field) = parse_bool(one(v, what), what); },
                   [field](const P& p) { return std::string(cref(p, field) ? "true" : "false"); }, {});
    }
    /// A number or a word meaning "none" (std::optional<double>: "auto", "none").
    template <class A>
    Spec& optional_real(std::string key, A field, std::string unit, std::string none_word, std::string help) {
        Option o = base(std::move(key), std::move(unit), std::move(help), Form::VALUE);
        o.type_name = "REAL|" + none_word;
        const std::string what = flag_name(o.key);
        return add(std::move(o),
                   [field, what, none_word](P& p, const std::vector<std::string>& v) {
                       const std::string& s = one(v, what);
                       if (s == none_word) {
                           ref(p, field).reset();
                           return;
                       }
                       ref(p, field) = parse_number(s, what + " (a number or '" + none_word + "')");
                   },
                   [field, none_word](const P& p) { return cref(p, field) ? shortest(*cref(p, field)) : none_word; },
                   [field, what, stage = m_stage](const P& p) {
                       if (cref(p, field) && !std::isfinite(*cref(p, field))) throw InputError(stage + ": " + what + " must be finite");
                   });
    }
    /// N numbers (std::array<double, N>).
    template <std::size_t N, class A>
    Spec& numbers(std::string key, A field, std::string unit, std::string help) {
        Option o = numbers_option(std::move(key), std::move(unit), std::move(help), N);
        const std::string what = flag_name(o.key);
        return add(std::move(o),
                   [field, what](P& p, const std::vector<std::string>& v) { ref(p, field) = parse_array<N>(v, what); },
                   [field](const P& p) { return join_numbers(cref(p, field)); }, {});
    }
    /// N numbers or none (std::optional<std::array<double, N>>); `none_text` in provenance.
    template <std::size_t N, class A>
    Spec& optional_numbers(std::string key, A field, std::string unit, std::string none_text, std::string help) {
        Option o = numbers_option(std::move(key), std::move(unit), std::move(help), N);
        const std::string what = flag_name(o.key);
        return add(std::move(o),
                   [field, what](P& p, const std::vector<std::string>& v) { ref(p, field) = parse_array<N>(v, what); },
                   [field, none_text](const P& p) { return cref(p, field) ? join_numbers(*cref(p, field)) : none_text; }, {});
    }
    /// Repeatable N-tuples (std::vector<std::array<double, N>>), ';' between tuples in provenance.
    template <std::size_t N, class A>
    Spec& tuples(std::string key, A field, std::string unit, std::string none_text, std::string help) {
        Option o = base(std::move(key), std::move(unit), std::move(help), Form::REPEATED);
        o.count = static_cast<int>(N);
        o.type_name = std::to_string(N) + "xREAL";
        const std::string what = flag_name(o.key);
        return add(std::move(o),
                   [field, what](P& p, const std::vector<std::string>& v) {
                       auto& out = ref(p, field);
                       out.clear();
                       for (const auto& s : v) out.push_back(parse_array<N>({s}, what + " '" + s + "'"));
                   },
                   [field, none_text](const P& p) {
                       std::string s;
                       for (const auto& a : cref(p, field)) s += (s.empty() ? "" : ";") + join_numbers(a);
                       return s.empty() ? none_text : s;
                   },
                   {});
    }
    /// A list of choices (std::vector<std::string>).
    template <class A>
    Spec& choice_list(std::string key, A field, std::vector<std::string> choices, std::string help) {
        Option o = base(std::move(key), "", std::move(help), Form::CHOICES);
        o.choices = choices;
        const std::string what = flag_name(o.key);
        return add(std::move(o),
                   [field](P& p, const std::vector<std::string>& v) {
                       auto& out = ref(p, field);
                       out.clear();
                       for (auto& w : split_commas(v)) {
                           if (!w.empty()) out.push_back(std::move(w));
                       }
                   },
                   [field](const P& p) {
                       std::string s;
                       for (const auto& w : cref(p, field)) s += (s.empty() ? "" : ",") + w;
                       return s;
                   },
                   [field, choices, what, stage = m_stage](const P& p) {
                       if (cref(p, field).empty()) throw InputError(stage + ": " + what + " needs at least one of " + list_words(choices));
                       for (const auto& w : cref(p, field)) check_choice(stage, what, w, choices);
                   });
    }
    /// One of named values of an enum: {{"sparse", SPARSE}, {"dense", DENSE}}.
    template <class E, class A>
    Spec& choice(std::string key, A field, std::vector<std::pair<std::string, E>> values, std::string help) {
        Option o = base(std::move(key), "", std::move(help), Form::VALUE);
        for (const auto& [w, e] : values) o.choices.push_back(w);
        const std::string what = flag_name(o.key);
        const std::string stage = m_stage;
        const auto words = o.choices;
        return add(std::move(o),
                   [field, what, values, stage, words](P& p, const std::vector<std::string>& v) {
                       const std::string& w = one(v, what);
                       for (const auto& [name, e] : values) {
                           if (name == w) {
                               ref(p, field) = e;
                               return;
                           }
                       }
                       check_choice(stage, what, w, words);
                   },
                   [field, values](const P& p) {
                       for (const auto& [name, e] : values) {
                           if (cref(p, field) == e) return name;
                       }
                       return std::string("?");
                   },
                   {});
    }
    /// An option with its own parsing and provenance text (planes, flags that clear a field).
    Spec& custom(Option o, Setter set, Shower show, Checker check = {}) {
        if (o.name.empty()) o.name = snake(o.key);
        return add(std::move(o), std::move(set), std::move(show), std::move(check));
    }
    /// The provenance name of the last option, when it differs from its key with '-' as '_'.
    Spec& named(std::string name) {
        m_entries.back().option.name = std::move(name);
        return *this;
    }
    /// The last option is an output-side choice (not a parameter of the result): not in provenance.
    Spec& not_provenance() {
        m_entries.back().option.provenance = false;
        return *this;
    }
    /// A rule that involves several options, checked after every option's own rule.
    Spec& rule(Checker c) {
        m_rules.push_back(std::move(c));
        return *this;
    }
    /// The options of another struct inside this one (a member reached by `part`).
    template <class Q, class F>
    Spec& include(const Spec<Q>& other, F part) {
        for (const auto& e : other.entries()) {
            Entry n;
            n.option = e.option;
            auto set = e.set;
            auto show = e.show;
            auto check = e.check;
            n.set = [set, part](P& p, const std::vector<std::string>& v) { set(part(p), v); };
            n.show = [show, part](const P& p) { return show(part(const_cast<P&>(p))); };
            if (check) n.check = [check, part](const P& p) { check(part(const_cast<P&>(p))); };
            m_entries.push_back(std::move(n));
        }
        for (const auto& r : other.m_rules) m_rules.push_back([r, part](const P& p) { r(part(const_cast<P&>(p))); });
        return *this;
    }

    /// Sets option `key` from its text values. @throws UnknownOptionError, InputError
    void set(P& p, const std::string& key, const std::vector<std::string>& values) const {
        for (const auto& e : m_entries) {
            if (e.option.key == key) {
                e.set(p, values);
                return;
            }
        }
        throw UnknownOptionError(m_stage + ": no option --" + key + " (expected one of: " + key_list() + ")");
    }
    /// Every option's rule in declaration order, then the rules across options. @throws InputError
    void validate(const P& p) const {
        for (const auto& e : m_entries) {
            if (e.check) e.check(p);
        }
        for (const auto& r : m_rules) r(p);
    }
    /// (name, value) of every provenance option, defaults included, in declaration order.
    std::vector<std::pair<std::string, std::string>> parameters(const P& p) const {
        std::vector<std::pair<std::string, std::string>> out;
        for (const auto& e : m_entries) {
            if (e.option.provenance) out.emplace_back(e.option.name, e.show(p));
        }
        return out;
    }
    std::string key_list() const {
        std::string s;
        for (const auto& e : m_entries) s += (s.empty() ? "" : ", ") + e.option.key;
        return s;
    }

private:
    template <class Q>
    friend class Spec;

    template <std::size_t N>
    static std::array<double, N> parse_array(const std::vector<std::string>& v, const std::string& what) {
        const auto x = parse_numbers(v, N, what);
        std::array<double, N> a{};
        std::copy(x.begin(), x.end(), a.begin());
        return a;
    }
    static std::string snake(std::string k) {
        for (auto& c : k) c = c == '-' ? '_' : c;
        return k;
    }
    static std::string flag_name(const std::string& key) { return "--" + key; }
    static const std::string& one(const std::vector<std::string>& v, const std::string& what) {
        if (v.size() != 1) throw InputError(what + ": expected one value, got " + std::to_string(v.size()));
        return v.front();
    }
    static std::string list_words(const std::vector<std::string>& w) {
        std::string s;
        for (std::size_t i = 0; i < w.size(); ++i) s += (i == 0 ? "" : i + 1 == w.size() ? " or " : ", ") + w[i];
        return s;
    }
    static void check_choice(const std::string& stage, const std::string& what, const std::string& v, const std::vector<std::string>& choices) {
        if (choices.empty()) return;
        for (const auto& c : choices) {
            if (c == v) return;
        }
        throw InputError(stage + ": " + what + " = '" + v + "': expected " + list_words(choices));
    }
    // A field is a member pointer of P or a function P& -> T&.
    template <class T>
    static T& ref(P& p, T P::*m) {
        return p.*m;
    }
    template <class F>
    static auto& ref(P& p, F f) {
        return f(p);
    }
    template <class F>
    static const auto& cref(const P& p, F f) {
        return ref(const_cast<P&>(p), f);
    }

    Option base(std::string key, std::string unit, std::string help, Form form) {
        Option o;
        o.name = snake(key);
        o.key = std::move(key);
        o.unit = std::move(unit);
        o.help = std::move(help);
        o.form = form;
        return o;
    }
    Option numbers_option(std::string key, std::string unit, std::string help, std::size_t n) {
        Option o = base(std::move(key), std::move(unit), std::move(help), Form::NUMBERS);
        o.count = static_cast<int>(n);
        o.type_name = "REAL";
        return o;
    }
    Spec& add(Option o, Setter set, Shower show, Checker check) {
        o.default_text = show(P{});
        m_entries.push_back({std::move(o), std::move(set), std::move(show), std::move(check)});
        return *this;
    }

    std::string m_stage;
    std::vector<Entry> m_entries;
    std::vector<Checker> m_rules;
};

}  // namespace opt
}  // namespace aneu
