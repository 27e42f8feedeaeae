#!/usr/bin/env bash
# deploy/security/make-pki.sh: DDS Security material for the cell (deploy/security/README.md).
#
#   make-pki.sh --out DIR [--days N] [--force] [--roles FILE] [--org NAME] [identity[=role] ...]
#
# Makes, in DIR: a CA (ca_cert.pem; its key in private/, mode 0700), per identity a certificate
# (<id>_cert.pem, RSA 2048) and key (private/<id>_key.pem), the signed governance
# (governance.p7s) and signed permissions (<id>_permissions.p7s) by role from roles.conf, and a
# Cyclone DDS config fragment holding only the <Security> part (<id>.xml) for
#   CYCLONEDDS_URI=file://<network xml>,file://DIR/<id>.xml
# Idempotent: existing keys and certificates are kept, documents are re-signed only when their
# text changed; --force remakes everything (a new CA: every other holder of the old PKI must be
# given the new one).
set -euo pipefail

readonly kScript="make-pki.sh"
readonly kHere="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
readonly kDefaultIdentities=(sim-7545 gateway.ibm7545 gateway.picker sim-excalibur
  gateway.excalibur motion sim-world camera.ibm7545_eye camera.belt_cam camera.assembly_cam vision
  calibration task echo monitor operator viewer)
readonly kDomainMin=0
readonly kDomainMax=230

out=""
days=3650
force=0
roles_file="${kHere}/roles.conf"
org="cell"
identity_args=()

die() {
  echo "${kScript}: error: $*" >&2
  exit 2
}
say() { echo "${kScript}: $*"; }

usage() {
  cat <<EOF
usage: ${kScript} --out DIR [--days N] [--force] [--roles FILE] [--org NAME] [identity[=role] ...]

  --out DIR      where the PKI goes (created; absolute paths of it end up in DIR/<id>.xml)
  --days N       validity of the CA, the certificates and the permissions (default 3650)
  --force        remake everything, the CA included
  --roles FILE   role table (default ${kHere}/roles.conf)
  --org NAME     O= of every subject (default cell); subjects are CN=<identity>,O=<org>
  identity       a service name (role from the 'identity' lines of the role table) or
                 name=role; none given: every service of the cell profiles plus
                 operator (operations) and viewer (monitor)
EOF
}

while (($#)); do
  case "$1" in
    --out) (($# >= 2)) || die "--out needs a directory"; out="$2"; shift 2 ;;
    --out=*) out="${1#--out=}"; shift ;;
    --days) (($# >= 2)) || die "--days needs a number"; days="$2"; shift 2 ;;
    --days=*) days="${1#--days=}"; shift ;;
    --roles) (($# >= 2)) || die "--roles needs a file"; roles_file="$2"; shift 2 ;;
    --roles=*) roles_file="${1#--roles=}"; shift ;;
    --org) (($# >= 2)) || die "--org needs a name"; org="$2"; shift 2 ;;
    --org=*) org="${1#--org=}"; shift ;;
    --force) force=1; shift ;;
    -h | --help) usage; exit 0 ;;
    -*) usage >&2; die "unknown option '$1'" ;;
    *) identity_args+=("$1"); shift ;;
  esac
done

[[ -n "${out}" ]] || { usage >&2; die "--out DIR is required"; }
[[ "${days}" =~ ^[1-9][0-9]{0,5}$ ]] || die "--days must be a whole number of days >= 1, got '${days}'"
[[ "${org}" =~ ^[A-Za-z0-9][A-Za-z0-9._-]*$ ]] || die "--org must be letters, digits, '._-', got '${org}'"
command -v openssl >/dev/null 2>&1 ||
  die "openssl not found in PATH: install it (apt-get install openssl)"
[[ -r "${roles_file}" ]] || die "role table '${roles_file}' not readable"

# ---- role table ------------------------------------------------------------------------------
declare -A role_publish=() role_subscribe=() role_include=() role_known=()
identity_globs=()
identity_roles=()
line_no=0
while IFS= read -r line || [[ -n "${line}" ]]; do
  line_no=$((line_no + 1))
  line="${line%%#*}"
  read -r -a f <<<"${line}" || true
  ((${#f[@]})) || continue
  where="${roles_file}:${line_no}"
  if [[ "${f[0]}" == identity ]]; then
    ((${#f[@]} == 3)) || die "${where}: 'identity' takes <glob> <role>, got '${line}'"
    identity_globs+=("${f[1]}")
    identity_roles+=("${f[2]}")
    continue
  fi
  ((${#f[@]} >= 3)) || die "${where}: expected '<role> publish|subscribe|include <names>...', got '${line}'"
  role="${f[0]}"
  [[ "${role}" =~ ^[a-z][a-z0-9-]*$ ]] || die "${where}: bad role name '${role}'"
  role_known[${role}]=1
  case "${f[1]}" in
    publish) role_publish[${role}]+=" ${f[*]:2}" ;;
    subscribe) role_subscribe[${role}]+=" ${f[*]:2}" ;;
    include) role_include[${role}]+=" ${f[*]:2}" ;;
    *) die "${where}: unknown verb '${f[1]}' (publish, subscribe or include)" ;;
  esac
done <"${roles_file}"
for role in "${!role_include[@]}"; do
  for inc in ${role_include[${role}]}; do
    [[ -n "${role_known[${inc}]:-}" ]] || die "${roles_file}: role '${role}' includes unknown role '${inc}'"
  done
done
for role in "${!role_known[@]}"; do  # an include cycle would recurse for ever
  queue="${role}" seen=" "
  while [[ -n "${queue// /}" ]]; do
    read -r cur queue <<<"${queue}"
    for inc in ${role_include[${cur}]:-}; do
      [[ "${inc}" != "${role}" ]] || die "${roles_file}: role '${role}' includes itself (through '${cur}')"
      [[ "${seen}" == *" ${inc} "* ]] || { seen+="${inc} "; queue+=" ${inc}"; }
    done
  done
done
for i in "${!identity_roles[@]}"; do
  [[ -n "${role_known[${identity_roles[$i]}]:-}" ]] ||
    die "${roles_file}: identity '${identity_globs[$i]}' names unknown role '${identity_roles[$i]}'"
done

# Topics of a role with its includes resolved: prints one topic per line, sorted, unique.
# (includes were checked above: known roles, no cycles). $1 role, $2 publish|subscribe
role_topics() {
  local role="$1" kind="$2" inc
  local -
  set -f  # a topic pattern such as '*' is not a file name glob
  if [[ "${kind}" == publish ]]; then
    printf '%s\n' ${role_publish[${role}]:-}
  else
    printf '%s\n' ${role_subscribe[${role}]:-}
  fi
  for inc in ${role_include[${role}]:-}; do
    role_topics "${inc}" "${kind}"
  done
}

role_of_name() {
  local name="$1" i
  for i in "${!identity_globs[@]}"; do
    # shellcheck disable=SC2053  # the glob is meant to match
    if [[ "${name}" == ${identity_globs[$i]} ]]; then
      echo "${identity_roles[$i]}"
      return 0
    fi
  done
  return 1
}

# ---- identities --------------------------------------------------------------------------------
((${#identity_args[@]})) || identity_args=("${kDefaultIdentities[@]}")
ids=()
declare -A id_role=()
for arg in "${identity_args[@]}"; do
  name="${arg%%=*}"
  [[ "${name}" =~ ^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$ ]] ||
    die "bad identity name '${name}' (in '${arg}'): letters, digits and '._-', starting with a letter or digit, at most 64"
  if [[ "${arg}" == *=* ]]; then
    role="${arg#*=}"
    [[ -n "${role_known[${role}]:-}" ]] ||
      die "unknown role '${role}' for identity '${name}'; roles in ${roles_file}: $(printf '%s ' "${!role_known[@]}" | tr ' ' '\n' | sort | tr '\n' ' ')"
  else
    role="$(role_of_name "${name}")" ||
      die "no role for identity '${name}': name it as ${name}=<role> or add an 'identity' line to ${roles_file}"
  fi
  [[ -z "${id_role[${name}]:-}" ]] || die "identity '${name}' given twice"
  id_role[${name}]="${role}"
  ids+=("${name}")
done

# ---- directory and CA ----------------------------------------------------------------------------
mkdir -p "${out}" || die "cannot create --out directory '${out}'"
out="$(cd "${out}" && pwd)"
priv="${out}/private"
if ((force)); then
  say "--force: removing the PKI in ${out}"
  rm -rf "${priv}"
  rm -f "${out}"/ca_cert.pem "${out}"/*_cert.pem "${out}"/*.p7s "${out}"/*.xml.new
  # Only the XML this script wrote: a network config kept beside it survives.
  for f in "${out}"/*.xml; do
    if [[ -f "${f}" ]] && grep -q 'Generated by deploy/security/make-pki.sh' "${f}"; then
      rm -f "${f}"
    fi
  done
fi
mkdir -p "${priv}"
chmod 0700 "${priv}"
umask 077

ssl() {  # openssl with its output kept for the error message
  local log
  if ! log="$(openssl "$@" 2>&1)"; then
    die "openssl $1 failed: ${log}"
  fi
}

ca_cert="${out}/ca_cert.pem"
ca_key="${priv}/ca_key.pem"
if [[ -s "${ca_cert}" && -s "${ca_key}" ]]; then
  say "CA: keeping ${ca_cert}"
else
  [[ ! -e "${out}/governance.p7s" ]] || rm -f "${out}"/*.p7s "${out}"/*_cert.pem
  say "CA: making ${ca_cert} (RSA 2048, ${days} days)"
  ssl genrsa -out "${ca_key}" 2048
  ssl req -x509 -new -key "${ca_key}" -sha256 -days "${days}" -out "${ca_cert}" \
    -subj "/O=${org}/CN=${org} DDS CA"
fi
chmod 0600 "${ca_key}"
chmod 0644 "${ca_cert}"

iso_date() {  # "notAfter=Jan  1 00:00:00 2035 GMT" -> 2035-01-01T00:00:00Z
  date -u -d "${1#*=}" +%Y-%m-%dT%H:%M:%SZ || die "cannot read certificate date '$1'"
}

# Signs $1.xml into $1.p7s when the text changed since the last signing (or the .p7s is gone).
sign_if_changed() {
  local base="$1" new="$1.xml.new"
  if [[ -s "${base}.p7s" && -s "${base}.xml" ]] && cmp -s "${new}" "${base}.xml"; then
    rm -f "${new}"
    return 1
  fi
  mv "${new}" "${base}.xml"
  ssl smime -sign -text -in "${base}.xml" -out "${base}.p7s" -signer "${ca_cert}" -inkey "${ca_key}"
  ssl smime -verify -text -in "${base}.p7s" -CAfile "${ca_cert}" -out /dev/null
  chmod 0644 "${base}.xml" "${base}.p7s"
  return 0
}

# ---- governance ---------------------------------------------------------------------------------
cat >"${out}/governance.xml.new" <<EOF
<?xml version="1.0" encoding="utf-8"?>
<!-- Generated by deploy/security/make-pki.sh: every topic authenticated, access-controlled and
     encrypted; no unauthenticated participant. -->
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"
     xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_governance.xsd">
  <domain_access_rules>
    <domain_rule>
      <domains><id_range><min>${kDomainMin}</min><max>${kDomainMax}</max></id_range></domains>
      <allow_unauthenticated_participants>false</allow_unauthenticated_participants>
      <enable_join_access_control>true</enable_join_access_control>
      <discovery_protection_kind>ENCRYPT</discovery_protection_kind>
      <liveliness_protection_kind>ENCRYPT</liveliness_protection_kind>
      <rtps_protection_kind>ENCRYPT</rtps_protection_kind>
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
if sign_if_changed "${out}/governance"; then
  say "governance: signed ${out}/governance.p7s"
else
  say "governance: keeping ${out}/governance.p7s"
fi

# ---- identities ------------------------------------------------------------------------------------
topics_xml() {  # $1 indent, then topics
  local indent="$1" t
  shift
  for t in "$@"; do
    printf '%s<topic>%s</topic>\n' "${indent}" "${t}"
  done
}

for id in "${ids[@]}"; do
  role="${id_role[${id}]}"
  cert="${out}/${id}_cert.pem"
  key="${priv}/${id}_key.pem"
  if [[ -s "${cert}" && -s "${key}" ]] && openssl verify -CAfile "${ca_cert}" "${cert}" >/dev/null 2>&1; then
    made="kept"
  else
    ssl genrsa -out "${key}" 2048
    ssl req -new -key "${key}" -out "${priv}/${id}.csr" -subj "/O=${org}/CN=${id}"
    ssl x509 -req -in "${priv}/${id}.csr" -CA "${ca_cert}" -CAkey "${ca_key}" \
      -CAcreateserial -CAserial "${priv}/ca_cert.srl" -sha256 -days "${days}" -out "${cert}"
    rm -f "${priv}/${id}.csr"
    made="made"
  fi
  chmod 0600 "${key}"
  chmod 0644 "${cert}"
  subject="$(openssl x509 -noout -subject -nameopt RFC2253 -in "${cert}")"
  subject="${subject#subject=}"
  not_before="$(iso_date "$(openssl x509 -noout -startdate -in "${cert}")")"
  not_after="$(iso_date "$(openssl x509 -noout -enddate -in "${cert}")")"

  mapfile -t pub < <(role_topics "${role}" publish | sed '/^$/d' | sort -u)
  mapfile -t sub < <(role_topics "${role}" subscribe | sed '/^$/d' | sort -u)
  {
    cat <<EOF
<?xml version="1.0" encoding="utf-8"?>
<!-- Generated by deploy/security/make-pki.sh from roles.conf: identity '${id}', role '${role}'. -->
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"
     xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_permissions.xsd">
  <permissions>
    <grant name="${id}_grant">
      <subject_name>${subject}</subject_name>
      <validity>
        <not_before>${not_before}</not_before>
        <not_after>${not_after}</not_after>
      </validity>
      <allow_rule>
        <domains><id_range><min>${kDomainMin}</min><max>${kDomainMax}</max></id_range></domains>
EOF
    if ((${#pub[@]})); then
      echo "        <publish>"
      echo "          <topics>"
      topics_xml "            " "${pub[@]}"
      echo "          </topics>"
      echo "          <partitions><partition>*</partition></partitions>"
      echo "        </publish>"
    fi
    if ((${#sub[@]})); then
      echo "        <subscribe>"
      echo "          <topics>"
      topics_xml "            " "${sub[@]}"
      echo "          </topics>"
      echo "          <partitions><partition>*</partition></partitions>"
      echo "        </subscribe>"
    fi
    cat <<EOF
      </allow_rule>
      <default>DENY</default>
    </grant>
  </permissions>
</dds>
EOF
  } >"${out}/${id}_permissions.xml.new"
  if sign_if_changed "${out}/${id}_permissions"; then
    signed="signed"
  else
    signed="kept"
  fi

  cat >"${out}/${id}.xml.new" <<EOF
<?xml version="1.0" encoding="UTF-8"?>
<!-- Generated by deploy/security/make-pki.sh: DDS Security of identity '${id}' (role '${role}').
     Only the <Security> part: use after a network config,
     CYCLONEDDS_URI=file://<network xml>,file://${out}/${id}.xml -->
<CycloneDDS xmlns="https://cdds.io/config">
  <Domain Id="any">
    <Security>
      <Authentication>
        <IdentityCA>file:${ca_cert}</IdentityCA>
        <IdentityCertificate>file:${cert}</IdentityCertificate>
        <PrivateKey>file:${key}</PrivateKey>
      </Authentication>
      <AccessControl>
        <PermissionsCA>file:${ca_cert}</PermissionsCA>
        <Governance>file:${out}/governance.p7s</Governance>
        <Permissions>file:${out}/${id}_permissions.p7s</Permissions>
      </AccessControl>
      <Cryptographic/>
    </Security>
  </Domain>
</CycloneDDS>
EOF
  mv "${out}/${id}.xml.new" "${out}/${id}.xml"
  chmod 0644 "${out}/${id}.xml"
  say "identity ${id}: role ${role}, subject ${subject}, certificate ${made}, permissions ${signed}" \
    "(${#pub[@]} publish, ${#sub[@]} subscribe rules) -> ${out}/${id}.xml"
done
say "done: ${#ids[@]} identities in ${out}"
