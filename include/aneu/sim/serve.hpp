// SPDX-License-Identifier: MIT
// `aneusim serve`: the simulator behind an OpenIGTLink server (the protocol of 3D Slicer's OpenIGTLinkIF and of
// the PLUS toolkit that bridges trackers and haptic devices). Message names and units: docs/openigtlink.md.
#pragma once

#include <functional>
#include <string>

#include "aneu/sim/simulator.hpp"

namespace aneu::sim {

struct ServeOptions {
    int port = 18944;            ///< 0: any free port (said through on_listening)
    bool deterministic = false;  ///< lockstep: the timeline follows the messages' time stamps (tests, replays)
    double max_seconds = 0.0;    ///< stop after this long (0: no limit)
    double idle_seconds = 10.0;  ///< stop after this long without any client (0: never); a client that leaves may come back
    double polydata_hz = 30.0;   ///< the deformed surface to the clients
    int max_clients = 2;         ///< a device bridge and a viewer
    bool ras = false;            ///< coordinates to and from the clients in RAS (3D Slicer's convention): x and y negated;
                                 ///< otherwise the bundle's frame (the CT's physical frame as ITK reads it: LPS)
    std::function<void(int port)> on_listening;  ///< called as the server's clock starts (real-time time stamps count from here)
    std::function<void(const std::string&)> on_message;
};

/// What the server received, sent and dropped (also in the session report, `igtl` object).
struct ServeCounters {
    long clients_connected = 0, clients_refused = 0, clients_lost = 0;
    long clients_stalled = 0;     ///< a send that could not go on for 2 s (a client that reads nothing, or is gone): dropped
    long messages = 0;            ///< well-formed messages received
    long poses = 0;               ///< TRANSFORMs turned into pose samples
    long poses_coalesced = 0;     ///< a newer pose of the same instrument arrived before the haptic loop took it
    long dropped_unknown = 0;     ///< unknown message type or device name
    long dropped_malformed = 0;   ///< a body that does not unpack (CRC, size) or a value that is not a number
    long dropped_oversize = 0;    ///< a declared body larger than any message this server takes (the client is dropped)
    long dropped_garbage = 0;     ///< bytes that are no OpenIGTLink header (the client is dropped)
    long forces_sent = 0, polydata_sent = 0, transforms_sent = 0, status_sent = 0;
    long strings_sent = 0;        ///< `<ins>.force` as text at the surface rate (for viewers without SENSOR: 3D Slicer)
    long v2_messages = 0;         ///< header-version-2 messages (3D Slicer's default) read: content taken, metadata set aside
    long forces_skipped = 0;      ///< haptic ticks whose force a slow client did not take in time (only the latest is kept)
};

/// Runs the scene (live_input) with poses, openings, buttons and actions from OpenIGTLink clients on loopback, and
/// sends each client the haptic force per instrument (SENSOR at the haptic rate; STRING at the surface rate), the
/// deformed surface, the instruments' (`<ins>.pose`) and clips' poses and a STATUS per event. Header versions 1 and 2
/// are read (version 2's metadata is set aside); everything sent is version 1. Returns when a client sends STRING `aneusim` = `stop`, after idle_seconds without a client, or
/// after max_seconds; the scene's outputs (log, series, report) are written as by run_scene.
/// @throws InputError the port cannot be opened
Assessment serve_scene(Simulator& sim, const ServeOptions& opt, ServeCounters* counters = nullptr);

}  // namespace aneu::sim
