#!/usr/bin/env bash
# VDMCheck2, the INTO-CPS formal checker of FMI 2.0 model descriptions (a VDM-SL model of the
# standard's XML rules, run by VDMJ), from Maven Central: org.into-cps.vdmcheck.fmi2:vdmcheck2.
# Maven Central has its jars, not the release zip; this lays them out as the zip does (its
# launcher looks for vdmj.jar, annotations.jar, xsd2vdm.jar, fmuReader.jar, fmi2-static-model/,
# fmi2-rule-model/ and fmi2schema/ beside vdmcheck2.jar).
#
# Usage: scripts/install_vdmcheck2.sh [DEST]   (default build-tools/vdmcheck2-<version>)
# Then:  java -jar DEST/vdmcheck2.jar file.fmu   -> "No errors found." and exit status 0
# Idempotent; needs java and mvn (scripts/setup.sh installs them). Sourced or run.
set -euo pipefail
VDMCHECK2_VERSION=${VDMCHECK2_VERSION:-1.1.3}
_root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
_dest=${1:-$_root/build-tools/vdmcheck2-$VDMCHECK2_VERSION}

if [ ! -f "$_dest/vdmcheck2.jar" ] || [ ! -d "$_dest/fmi2-rule-model" ]; then
  command -v mvn >/dev/null || { echo "install_vdmcheck2: mvn (Maven) is missing" >&2; exit 1; }
  command -v java >/dev/null || { echo "install_vdmcheck2: java is missing" >&2; exit 1; }
  _tmp=$(mktemp -d)
  cat > "$_tmp/pom.xml" <<EOF
<project xmlns="http://maven.apache.org/POM/4.0.0">
  <modelVersion>4.0.0</modelVersion>
  <groupId>local.ipmsm-fmu</groupId>
  <artifactId>vdmcheck2-install</artifactId>
  <version>1</version>
  <packaging>pom</packaging>
  <dependencies>
    <dependency>
      <groupId>org.into-cps.vdmcheck.fmi2</groupId>
      <artifactId>vdmcheck2</artifactId>
      <version>$VDMCHECK2_VERSION</version>
    </dependency>
  </dependencies>
</project>
EOF
  mvn -q -B -Dstyle.color=never -f "$_tmp/pom.xml" dependency:copy-dependencies \
    -DoutputDirectory="$_tmp/jars" -Dmdep.stripVersion=true -DincludeScope=runtime
  rm -rf "$_dest.tmp" && mkdir -p "$_dest.tmp"
  for j in vdmcheck2 vdmj annotations xsd2vdm fmuReader; do
    cp "$_tmp/jars/$j.jar" "$_dest.tmp/$j.jar"
  done
  # the VDM-SL models and the XSD, unpacked beside the jars
  python3 - "$_tmp/jars" "$_dest.tmp" <<'EOF'
import sys, zipfile
jars, dest = sys.argv[1], sys.argv[2]
for jar, prefix in (("static-model", "fmi2-static-model/"), ("rule-model", "fmi2-rule-model/"),
                    ("vdmcheck2", "fmi2schema/")):
    with zipfile.ZipFile(f"{jars}/{jar}.jar") as z:
        z.extractall(dest, [n for n in z.namelist() if n.startswith(prefix)])
EOF
  rm -rf "$_dest" && mv "$_dest.tmp" "$_dest"
  rm -rf "$_tmp"
fi
export IPMSM_VDMCHECK2_JAR="$_dest/vdmcheck2.jar"
