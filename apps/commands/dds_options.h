#pragma once
// The DDS transport options, declared once and added to every command that joins Fast DDS
// (`coordinator`, `worker`, `train --local-workers`, `monitor --domain`); proto/dds/dds_flags.h
// checks what they hold.

#include <CLI/CLI.hpp>

#include "proto/dds/dds_flags.h"

namespace poseforest::apps::commands {

/// Declares --profile, --peers, --interfaces, --dds-xml, --dds-profile, --discovery-server and
/// --security on `app` (group "DDS transport"), bound to `out`.
void AddDdsOptions(CLI::App& app, proto::dds::DdsSettings* out);

}  // namespace poseforest::apps::commands
