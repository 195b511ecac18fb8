#!/usr/bin/env bash
# make_security.sh — DDS-Security material for Reflex (Fast DDS 2.9 built-in plugins).
#
# Makes, in OUT_DIR (default: <repo>/out/security, never committed — it holds private keys):
#   ca/ca.cert.pem, ca/ca.key.pem            the Reflex certificate authority (ECDSA P-256, self-signed);
#                                            it is both the identity CA and the permissions CA
#   intruder_ca/ca.cert.pem, .key.pem        a DIFFERENT CA, only for tests (the "intruder" identity)
#   <module>/cert.pem, <module>/key.pem      identity of each module: vision, behavior, controller,
#                                            recorder, player, view (CA-signed) and intruder
#                                            (intruder-CA-signed)
#   governance.xml, governance.p7s           domain rules (authentication required, discovery +
#                                            liveliness encrypted, RTPS messages signed, every
#                                            topic access-controlled and encrypted), S/MIME-signed
#   <module>/permissions.xml, .p7s           what each module may publish / subscribe, S/MIME-signed
#   profiles/<module>.xml                    a COMPLETE Reflex profiles file for that module's process:
#                                            the QoS profiles of bringup/dds/reflex_profiles.xml, with
#                                            the participant profiles reflex_participant and
#                                            reflex_participant_udp carrying the module's security
#                                            properties (so `--profiles profiles/<module>.xml` alone
#                                            makes a process secure)
#   profiles/participants.xml                only participant profiles reflex_secure_<module> (one per
#                                            identity), for processes or tests that hold several
#                                            identities and load the QoS profiles from the base file
#
# A private key found readable by group or others is refused (exit 1, naming it): it may have been
# copied; --force remakes everything, chmod 600 accepts it.
# Idempotent: existing keys and certificates are kept while they still verify against their CA;
# XML documents are rewritten, and re-signed only when their text changed or their signature no
# longer verifies. --force makes everything anew (new CA: every module needs the new files).
#
# Paths inside the profiles are absolute file:// URIs: run the script again after moving OUT_DIR.
# Fast DDS 2.9 cannot combine DDS-Security with the discovery server: secure runs use simple
# discovery (the default of these participant profiles). See bringup/security/README.md.
set -euo pipefail

usage() {
  cat <<'EOF'
usage: make_security.sh [--force] [--base-profiles FILE] [--days N] [OUT_DIR]

Makes the DDS-Security material of Reflex (CA, identities, signed governance and permissions,
secure Fast DDS participant profiles) into OUT_DIR (default: <repo>/out/security).

  --force               regenerate everything, CA included (also the answer to a refused key:
                        a private key readable by group or others stops the script)
  --base-profiles FILE  QoS profiles copied into profiles/<module>.xml
                        (default: <repo>/bringup/dds/reflex_profiles.xml)
  --days N              validity of new certificates and of the permissions, days (default 3650)
  -h, --help            this help
EOF
}

die() { echo "make_security.sh: error: $*" >&2; exit 1; }

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
repo="$(cd "$here/../.." && pwd)"
out=""
force=0
days=3650
base_profiles="$repo/bringup/dds/reflex_profiles.xml"

while [[ $# -gt 0 ]]; do
  case "$1" in
    -h|--help) usage; exit 0 ;;
    --force) force=1; shift ;;
    --base-profiles)
      [[ $# -ge 2 ]] || die "--base-profiles needs a file"
      base_profiles="$2"; shift 2 ;;
    --days)
      [[ $# -ge 2 ]] || die "--days needs a number"
      [[ "$2" =~ ^[1-9][0-9]{0,4}$ ]] || die "--days '$2' is not a positive integer (1..99999)"
      days="$2"; shift 2 ;;
    -*) die "unknown option '$1' (see --help)" ;;
    *)
      [[ -z "$out" ]] || die "more than one output folder given ('$out' and '$1')"
      out="$1"; shift ;;
  esac
done
[[ -n "$out" ]] || out="$repo/out/security"
command -v openssl >/dev/null || die "openssl not found (Debian package 'openssl')"
command -v python3 >/dev/null || die "python3 not found (Debian package 'python3')"
[[ -r "$base_profiles" ]] || die "cannot read the base profiles file '$base_profiles'"

mkdir -p "$out" || die "cannot create the output folder '$out'"
out="$(cd "$out" && pwd)"
umask 077   # private keys are readable by the owner only

modules=(vision behavior controller recorder player view robot)
identities=("${modules[@]}" intruder)

# ---- private keys found with loose permissions -----------------------------------------------
# A private key readable by anyone but its owner may have been copied: it is not repaired silently
# (a chmod would hide that it was exposed). Without --force the script refuses, naming every such
# key and its mode; the operator either makes new material (--force: new CA and identities) or,
# knowing nobody else could read it, restricts it (chmod 600) and runs the script again.
if [[ $force -eq 0 ]]; then
  loose=()
  for key in "$out/ca/ca.key.pem" "$out/intruder_ca/ca.key.pem" "$out"/*/key.pem; do
    [[ -e "$key" ]] || continue
    mode="$(stat -c '%a' "$key")" || die "cannot read the mode of '$key'"
    if (( 8#$mode & 8#077 )); then loose+=("'$key' (mode 0$mode)"); fi
  done
  if [[ ${#loose[@]} -gt 0 ]]; then
    die "private key(s) readable by group or others: ${loose[*]}; a key others could read may have been" \
        "copied: make new material with --force, or, if you know nobody else read it, chmod 600 it and run" \
        "again"
  fi
fi

# ---- certificate authorities -----------------------------------------------------------------

# make_ca DIR COMMON_NAME: self-signed ECDSA P-256 CA (kept if present, unless --force).
make_ca() {
  local dir="$1" cn="$2"
  mkdir -p "$dir"
  if [[ $force -eq 0 && -s "$dir/ca.cert.pem" && -s "$dir/ca.key.pem" ]]; then
    return 0
  fi
  openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:P-256 -out "$dir/ca.key.pem" 2>/dev/null
  openssl req -x509 -new -sha256 -key "$dir/ca.key.pem" -days "$days" -subj "/CN=$cn" \
    -addext "basicConstraints=critical,CA:TRUE" -addext "keyUsage=critical,digitalSignature,keyCertSign,cRLSign" \
    -out "$dir/ca.cert.pem"
  echo "made CA '$cn' in $dir"
}

# make_identity NAME CA_DIR: key + certificate CN=reflex.NAME signed by the CA (kept if it verifies).
make_identity() {
  local name="$1" ca="$2" dir="$out/$1"
  mkdir -p "$dir"
  if [[ $force -eq 0 && -s "$dir/key.pem" && -s "$dir/cert.pem" ]] &&
     openssl verify -CAfile "$ca/ca.cert.pem" "$dir/cert.pem" >/dev/null 2>&1; then
    return 0
  fi
  openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:P-256 -out "$dir/key.pem" 2>/dev/null
  openssl req -new -sha256 -key "$dir/key.pem" -subj "/CN=reflex.$name" -out "$dir/cert.csr"
  openssl x509 -req -sha256 -in "$dir/cert.csr" -CA "$ca/ca.cert.pem" -CAkey "$ca/ca.key.pem" \
    -CAcreateserial -days "$days" -out "$dir/cert.pem" 2>/dev/null
  rm -f "$dir/cert.csr"
  echo "made identity reflex.$name ($dir)"
}

# sign_if_changed XML P7S CA_DIR NEW_TEXT: writes XML, signs it (S/MIME, clear text) when its text
# changed, when the signature is missing, or when it no longer verifies against the CA.
sign_if_changed() {
  local xml="$1" p7s="$2" ca="$3" text="$4"
  local changed=1
  if [[ -f "$xml" ]] && [[ "$(cat "$xml")" == "$text" ]]; then changed=0; fi
  if [[ $changed -eq 1 ]]; then printf '%s\n' "$text" > "$xml"; fi
  if [[ $force -eq 0 && $changed -eq 0 && -s "$p7s" ]] &&
     openssl smime -verify -in "$p7s" -CAfile "$ca/ca.cert.pem" -out /dev/null >/dev/null 2>&1; then
    return 0
  fi
  openssl smime -sign -text -in "$xml" -out "$p7s" -signer "$ca/ca.cert.pem" -inkey "$ca/ca.key.pem"
}

if [[ $force -eq 1 ]]; then
  rm -rf "$out/ca" "$out/intruder_ca" "$out/profiles" "$out/governance.xml" "$out/governance.p7s"
  for id in "${identities[@]}"; do rm -rf "${out:?}/$id"; done
fi

make_ca "$out/ca" "Reflex CA"
make_ca "$out/intruder_ca" "Intruder CA"
# A CA that was just remade invalidates every identity signed by the old one: make_identity
# notices (the certificate no longer verifies) and makes a new one.
for m in "${modules[@]}"; do make_identity "$m" "$out/ca"; done
make_identity intruder "$out/intruder_ca"

# ---- governance ------------------------------------------------------------------------------
# One rule for every domain id (0..232, the range reflex::bus accepts) and every topic:
#  - only authenticated participants take part (allow_unauthenticated_participants false) and a
#    participant needs valid permissions to join (enable_join_access_control);
#  - discovery and liveliness traffic encrypted, every RTPS message signed (origin authenticated);
#  - every topic: discovery and liveliness protected, read and write access controlled by the
#    permissions, metadata and data encrypted (AES-GCM).
governance_text() {
  cat <<'EOF'
<?xml version="1.0" encoding="UTF-8"?>
<!-- Reflex DDS-Security governance (generated by bringup/security/make_security.sh). -->
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"
     xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_governance.xsd">
  <domain_access_rules>
    <domain_rule>
      <domains>
        <id_range><min>0</min><max>232</max></id_range>
      </domains>
      <allow_unauthenticated_participants>false</allow_unauthenticated_participants>
      <enable_join_access_control>true</enable_join_access_control>
      <discovery_protection_kind>ENCRYPT</discovery_protection_kind>
      <liveliness_protection_kind>ENCRYPT</liveliness_protection_kind>
      <rtps_protection_kind>SIGN</rtps_protection_kind>
      <topic_access_rules>
        <topic_rule>
          <topic_expression>*</topic_expression>
          <enable_discovery_protection>true</enable_discovery_protection>
          <enable_liveliness_protection>true</enable_liveliness_protection>
          <enable_read_access_control>true</enable_read_access_control>
          <enable_write_access_control>true</enable_write_access_control>
          <metadata_protection_kind>ENCRYPT</metadata_protection_kind>
          <data_protection_kind>ENCRYPT</data_protection_kind>
        </topic_rule>
      </topic_access_rules>
    </domain_rule>
  </domain_access_rules>
</dds>
EOF
}
sign_if_changed "$out/governance.xml" "$out/governance.p7s" "$out/ca" "$(governance_text)"

# ---- permissions -----------------------------------------------------------------------------
# Topic names: idl/README.md. Every module publishes and reads reflex/heartbeat.
declare -A publish subscribe
publish[vision]="reflex/object_targets reflex/camera_left reflex/heartbeat"
subscribe[vision]="reflex/heartbeat"
publish[behavior]="reflex/hand_targets reflex/motion_priority reflex/body_schema reflex/walk_command reflex/heartbeat"
subscribe[behavior]="reflex/object_targets reflex/joint_state reflex/control_status reflex/heartbeat"
# reflex/controller_protection: what protects the robot; each controller also reads it to find a
# second controller on the domain.
# With a robot over DDS (--robot dds) the controller commands the robot and reads its state.
publish[controller]="reflex/joint_state reflex/control_status reflex/heartbeat reflex/controller_protection reflex/joint_command"
subscribe[controller]="reflex/hand_targets reflex/motion_priority reflex/body_schema reflex/walk_command reflex/heartbeat reflex/controller_protection reflex/robot_state"
# The robot's driver (reflex_mujoco, or a real robot's): the only identity that may write the robot
# state the controller computes from, and read the commands. The controller binds only a writer
# authenticated as this identity.
publish[robot]="reflex/robot_state reflex/robot_contacts reflex/heartbeat"
subscribe[robot]="reflex/joint_command reflex/heartbeat"
# The recorder only listens (every topic); it may announce itself with a heartbeat.
publish[recorder]="reflex/heartbeat"
subscribe[recorder]="reflex/object_targets reflex/camera_left reflex/hand_targets reflex/motion_priority reflex/body_schema reflex/walk_command reflex/joint_state reflex/control_status reflex/heartbeat reflex/controller_protection reflex/robot_state reflex/joint_command reflex/robot_contacts"
# The player (reflex_play) republishes recorded OBSERVATIONS only: what vision saw and what the
# robot did, so a recording can re-run behavior modules and feed monitoring. Not the four command
# topics the controller obeys (a recording replayed in a secure system never commands the robot),
# not reflex/heartbeat (replayed heartbeats carry other modules' names and would keep a silent
# source alive for the controller's staleness check). It reads nothing.
publish[player]="reflex/object_targets reflex/camera_left reflex/joint_state reflex/control_status"
subscribe[player]=""
# The live view (reflex_view) only reads what it draws: it has no publish rule at all, so Fast DDS
# refuses to create any writer for it (not even a heartbeat), and its samples could not be accepted.
publish[view]=""
subscribe[view]="reflex/joint_state reflex/control_status reflex/hand_targets reflex/object_targets reflex/camera_left reflex/controller_protection reflex/body_schema"
# The intruder asks for everything, but its identity and permissions come from another CA.
all_topics="${subscribe[recorder]}"
publish[intruder]="$all_topics"
subscribe[intruder]="$all_topics"

topics_xml() {
  local t
  for t in $1; do printf '            <topic>%s</topic>\n' "$t"; done
}

# criteria_xml publish|subscribe "TOPICS": the <publish> / <subscribe> element of an allow rule;
# nothing for an empty list (Fast DDS refuses a <topics> element without a <topic>, and an absent
# element grants nothing under <default>DENY</default>).
criteria_xml() {
  local kind="$1" topics="$2"
  [[ -n "$topics" ]] || return 0
  printf '        <%s>\n          <topics>\n' "$kind"
  topics_xml "$topics"
  printf '          </topics>\n        </%s>\n' "$kind"
}

not_before="$(date -u -d '1 day ago' +%Y-%m-%dT00:00:00)"
not_after="$(date -u -d "$days days" +%Y-%m-%dT00:00:00)"

permissions_text() {
  local name="$1"
  # The validity dates are kept from an existing document so that a re-run does not re-sign it.
  local nb="$not_before" na="$not_after" old="$out/$name/permissions.xml"
  if [[ $force -eq 0 && -f "$old" ]]; then
    nb="$(sed -n 's:.*<not_before>\(.*\)</not_before>.*:\1:p' "$old")"
    na="$(sed -n 's:.*<not_after>\(.*\)</not_after>.*:\1:p' "$old")"
    [[ -n "$nb" && -n "$na" ]] || { nb="$not_before"; na="$not_after"; }
  fi
  cat <<EOF
<?xml version="1.0" encoding="UTF-8"?>
<!-- Reflex DDS-Security permissions of '$name' (generated by bringup/security/make_security.sh). -->
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"
     xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_permissions.xsd">
  <permissions>
    <grant name="reflex.$name">
      <subject_name>CN=reflex.$name</subject_name>
      <validity>
        <not_before>$nb</not_before>
        <not_after>$na</not_after>
      </validity>
      <allow_rule>
        <domains>
          <id_range><min>0</min><max>232</max></id_range>
        </domains>
$(criteria_xml publish "${publish[$name]}"; criteria_xml subscribe "${subscribe[$name]}")
      </allow_rule>
      <default>DENY</default>
    </grant>
  </permissions>
</dds>
EOF
}

for m in "${modules[@]}"; do
  sign_if_changed "$out/$m/permissions.xml" "$out/$m/permissions.p7s" "$out/ca" "$(permissions_text "$m")"
done
# The intruder's governance and permissions are signed by its own CA (it holds no Reflex document).
sign_if_changed "$out/intruder/governance.xml" "$out/intruder/governance.p7s" "$out/intruder_ca" "$(governance_text)"
sign_if_changed "$out/intruder/permissions.xml" "$out/intruder/permissions.p7s" "$out/intruder_ca" \
  "$(permissions_text intruder)"

# ---- Fast DDS participant profiles -----------------------------------------------------------
mkdir -p "$out/profiles"
umask 022

# properties_xml NAME INDENT: the <propertiesPolicy> of identity NAME.
properties_xml() {
  local name="$1" ca="$out/ca" gov="$out/governance.p7s"
  if [[ "$name" == intruder ]]; then ca="$out/intruder_ca"; gov="$out/intruder/governance.p7s"; fi
  local -a props=(
    "dds.sec.auth.plugin=builtin.PKI-DH"
    "dds.sec.auth.builtin.PKI-DH.identity_ca=file://$ca/ca.cert.pem"
    "dds.sec.auth.builtin.PKI-DH.identity_certificate=file://$out/$name/cert.pem"
    "dds.sec.auth.builtin.PKI-DH.private_key=file://$out/$name/key.pem"
    "dds.sec.access.plugin=builtin.Access-Permissions"
    "dds.sec.access.builtin.Access-Permissions.permissions_ca=file://$ca/ca.cert.pem"
    "dds.sec.access.builtin.Access-Permissions.governance=file://$gov"
    "dds.sec.access.builtin.Access-Permissions.permissions=file://$out/$name/permissions.p7s"
    "dds.sec.crypto.plugin=builtin.AES-GCM-GMAC"
  )
  echo "        <propertiesPolicy>"
  echo "          <properties>"
  local p
  for p in "${props[@]}"; do
    printf '            <property><name>%s</name><value>%s</value></property>\n' "${p%%=*}" "${p#*=}"
  done
  echo "          </properties>"
  echo "        </propertiesPolicy>"
}

# participant_xml PROFILE_NAME NAME UDP_ONLY
participant_xml() {
  local profile="$1" name="$2" udp="$3"
  echo "    <participant profile_name=\"$profile\">"
  echo "      <rtps>"
  echo "        <name>reflex.$name</name>"
  if [[ "$udp" == 1 ]]; then
    echo "        <userTransports><transport_id>reflex_udpv4</transport_id></userTransports>"
    echo "        <useBuiltinTransports>false</useBuiltinTransports>"
  fi
  properties_xml "$name"
  echo "      </rtps>"
  echo "    </participant>"
}

# Per-module complete profiles file: the base file with its participant profiles replaced.
for id in "${identities[@]}"; do
  secure="$(participant_xml reflex_participant "$id" 0; participant_xml reflex_participant_udp "$id" 1)"
  SECURE="$secure" python3 - "$base_profiles" "$out/profiles/$id.xml" "$id" <<'PY'
import os, re, sys
base, dest, name = sys.argv[1], sys.argv[2], sys.argv[3]
text = open(base, encoding="utf-8").read()
stripped, n = re.subn(r'[ \t]*<participant\s+profile_name="[^"]*">.*?</participant>[ \t]*\n?', '', text,
                      flags=re.S)
if "</profiles>" not in stripped:
    sys.exit(f"make_security.sh: error: no </profiles> element in the base profiles file '{base}'")
note = (f"    <!-- Secure participant profiles of '{name}' (generated by bringup/security/"
        f"make_security.sh; the {n} plain participant profiles of the base file were removed). -->\n")
stripped = stripped.replace("</profiles>", note + os.environ["SECURE"] + "\n  </profiles>", 1)
open(dest, "w", encoding="utf-8").write(stripped)
PY
done

# participants.xml: reflex_secure_<name> for every identity (UDP + shared memory, like reflex_participant).
{
  echo '<?xml version="1.0" encoding="UTF-8"?>'
  echo '<!-- Secure participant profiles of every Reflex identity (generated by bringup/security/make_security.sh).'
  echo '     Only participant profiles: load the QoS profiles (bringup/dds/reflex_profiles.xml) too. -->'
  echo '<dds xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">'
  echo '  <profiles>'
  for id in "${identities[@]}"; do participant_xml "reflex_secure_$id" "$id" 0; done
  echo '  </profiles>'
  echo '</dds>'
} > "$out/profiles/participants.xml"

echo "security material in $out (profiles: $out/profiles/<module>.xml)"
