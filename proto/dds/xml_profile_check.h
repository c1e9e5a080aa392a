#pragma once
// Checks a Fast DDS XML participant profile without creating a participant (nothing joins DDS):
// `poseforest coordinator|worker --check-config` and the commands' start-up checks use it so that
// a wrong file or profile name is an error naming both before any process is started.

#include <string>
#include <vector>

#include "runtime/core/result.h"

namespace poseforest::proto::dds {

struct XmlProfileInfo {
  /// The profile sets DDS-Security properties (dds.sec.*) itself.
  bool has_security = false;
  /// The profile's discovery protocol is CLIENT or SUPER_CLIENT (a discovery server).
  bool discovery_client = false;
};

/// Loads `xml_file` with Fast DDS's own parser and looks up participant profile `profile`.
/// Errors: kIo (file missing or unreadable), kInvalidArgument (Fast DDS refuses the XML),
/// kNotFound (no such participant profile; the message lists the file's participant profiles),
/// kIo for a `file://` property of the profile (security credentials) that cannot be read.
core::Result<XmlProfileInfo> CheckXmlParticipantProfile(const std::string& xml_file,
                                                        const std::string& profile);

/// profile_name of every <participant> element of an XML profiles text, in order (a plain scan
/// of the text, for error messages and listings).
std::vector<std::string> ParticipantProfileNames(const std::string& xml_text);

}  // namespace poseforest::proto::dds
