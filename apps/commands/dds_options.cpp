#include "apps/commands/dds_options.h"

namespace poseforest::apps::commands {

void AddDdsOptions(CLI::App& app, proto::dds::DdsSettings* out) {
  // docs/distributed/README.md says more; every participant of a job needs the same settings.
  const char* group = "DDS transport (docs/distributed/README.md; the same on every participant of a job)";
  app.add_option("--profile", out->profile,
                 "built-in transports: shm (shared memory, the default), udp (UDP only), default (both)")
      ->type_name("shm|udp|default")
      ->group(group);
  app.add_option("--peers", out->peers, "--profile udp: initial peers (hosts without multicast)")
      ->type_name("HOST[:PORT],...")
      ->group(group);
  app.add_option("--interfaces", out->interfaces,
                 "--profile udp or --discovery-server: local IPv4 addresses to use")
      ->type_name("IP,...")
      ->group(group);
  app.add_option("--dds-xml", out->dds_xml,
                 "a Fast DDS XML participant profile instead, with --dds-profile\n"
                 "(deploy/fastdds/profiles.xml); env POSEFOREST_DDS_XML and POSEFOREST_DDS_PROFILE\n"
                 "stand in for them unless a transport option is given")
      ->type_name("FILE")
      ->group(group);
  app.add_option("--dds-profile", out->dds_profile, "the participant profile of --dds-xml")
      ->type_name("NAME")
      ->group(group);
  app.add_option("--discovery-server", out->discovery_server,
                 "discovery through `fast-discovery-server -i ID` (UDP; ID 0..255, default 0; port\n"
                 "11811): a client of every server listed (redundant servers: 0@IP0,1@IP1).\n"
                 "HOST: an IPv4 address or a host name, resolved (IPv4) once at start-up and shown;\n"
                 "a name that does not resolve exits 2. IPv6 is not supported.")
      ->type_name("[ID@]HOST[:PORT],...")
      ->group(group);
  app.add_option("--security", out->security,
                 "DDS-Security (authentication, access control, encryption): DIR/cert.pem, key.pem,\n"
                 "permissions.p7s and identity_ca.pem, permissions_ca.pem, governance.p7s in DIR or\n"
                 "DIR/.. (deploy/security/make-test-ca.sh OUT NAME -> --security OUT/NAME)")
      ->type_name("DIR")
      ->group(group);
}

}  // namespace poseforest::apps::commands
