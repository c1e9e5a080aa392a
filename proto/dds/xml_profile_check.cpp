#include "proto/dds/xml_profile_check.h"

#include <cstdio>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/domain/qos/DomainParticipantQos.hpp>
#include <fastdds/dds/log/Log.hpp>
#include <fstream>
#include <regex>
#include <sstream>

#include "proto/dds/dds_node.h"

namespace poseforest::proto::dds {

namespace fdds = eprosima::fastdds::dds;
using core::ErrorCode;
using core::Status;

std::vector<std::string> ParticipantProfileNames(const std::string& xml_text) {
  // Comments may mention profiles that do not exist: drop them first.
  static const std::regex comment("<!--[\\s\\S]*?-->");
  const std::string text = std::regex_replace(xml_text, comment, "");
  static const std::regex participant("<participant\\b[^>]*\\bprofile_name\\s*=\\s*\"([^\"]*)\"");
  std::vector<std::string> names;
  for (auto it = std::sregex_iterator(text.begin(), text.end(), participant); it != std::sregex_iterator();
       ++it)
    names.push_back((*it)[1].str());
  return names;
}

core::Result<XmlProfileInfo> CheckXmlParticipantProfile(const std::string& xml_file,
                                                        const std::string& profile) {
  std::ifstream in(xml_file);
  if (!in) return Status(ErrorCode::kIo, "cannot read Fast DDS XML profiles file " + xml_file);
  std::stringstream text;
  text << in.rdbuf();
  ConfigureDdsLogging();  // Fast DDS's parser errors: plain lines on stderr, before ours
  auto* factory = fdds::DomainParticipantFactory::get_instance();
  if (factory->load_XML_profiles_file(xml_file) != ReturnCode_t::RETCODE_OK) {
    fdds::Log::Flush();
    return Status(ErrorCode::kInvalidArgument,
                  "Fast DDS cannot parse the XML profiles in " + xml_file + " (its errors above say where)");
  }
  fdds::DomainParticipantQos qos;
  if (factory->get_participant_qos_from_profile(profile, qos) != ReturnCode_t::RETCODE_OK) {
    std::string known;
    for (const std::string& n : ParticipantProfileNames(text.str())) known += (known.empty() ? "" : ", ") + n;
    return Status(ErrorCode::kNotFound, "no participant profile '" + profile + "' in " + xml_file +
                                            (known.empty() ? " (it has none)" : " (it has: " + known + ")"));
  }
  XmlProfileInfo info;
  for (const auto& p : qos.properties().properties()) {
    if (p.name().rfind("dds.sec.", 0) == 0) info.has_security = true;
    const std::string& v = p.value();
    if (v.rfind("file://", 0) == 0) {
      const std::string path = v.substr(7);
      if (FILE* f = std::fopen(path.c_str(), "rb"))
        std::fclose(f);
      else
        return Status(ErrorCode::kIo, "profile '" + profile + "' in " + xml_file + ": property " + p.name() +
                                          " names " + v + ", which cannot be read");
    }
  }
  const auto protocol = qos.wire_protocol().builtin.discovery_config.discoveryProtocol;
  info.discovery_client = protocol == eprosima::fastrtps::rtps::DiscoveryProtocol_t::CLIENT ||
                          protocol == eprosima::fastrtps::rtps::DiscoveryProtocol_t::SUPER_CLIENT;
  return info;
}

}  // namespace poseforest::proto::dds
