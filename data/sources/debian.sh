#!/usr/bin/env bash
# Fetch a Debian game-data package and extract it for `photomat library import`
# (docs/data.md, "Sources"): `apt-get download` (no root needed), `dpkg -x`, and a
# photomat-source.json beside the extracted tree with the package's name, version and the
# .deb's SHA-256, which the importer records in every material's provenance.
#
#   data/sources/debian.sh redeclipse-data            # → sources/redeclipse-data/
#   data/sources/debian.sh 0ad-data /data/sources/0ad # → that folder
#   photomat library import sources/redeclipse-data sources/0ad-data --out library
#
# The .deb is kept in DIR/../.debs/ so that a second run extracts without downloading.
# nexuiz-textures (and nexuiz-data, which ships the same textures) are refused: they are held
# back for independent checks of what photomat learns.
set -euo pipefail

if [[ $# -lt 1 || $# -gt 2 || "$1" == -* ]]; then
    echo "usage: $0 PACKAGE [DIR]   (DIR defaults to sources/PACKAGE)" >&2
    exit 2
fi
package="$1"
dir="${2:-sources/$package}"
case "$package" in
    nexuiz-textures | nexuiz-data)
        echo "error: $package is held back for independent checks; it must not enter a material library" >&2
        exit 1
        ;;
esac
for tool in apt-get dpkg dpkg-deb sha256sum; do
    command -v "$tool" >/dev/null || { echo "error: $tool is needed (a Debian or Ubuntu system)" >&2; exit 1; }
done
if [[ -e "$dir" && -n "$(ls -A "$dir" 2>/dev/null)" ]]; then
    echo "error: $dir is not empty; remove it or give another folder" >&2
    exit 1
fi

debs="$(dirname "$dir")/.debs"
mkdir -p "$debs"
deb="$(ls "$debs/${package}"_*.deb 2>/dev/null | head -1 || true)"
if [[ -z "$deb" ]]; then
    echo "== downloading $package into $debs" >&2
    (cd "$debs" && apt-get download "$package")
    deb="$(ls "$debs/${package}"_*.deb | head -1)"
fi
version="$(dpkg-deb -f "$deb" Version)"
sha="$(sha256sum "$deb" | cut -d' ' -f1)"
# Extract into a temporary folder beside DIR, then rename: a killed run leaves no half tree.
tmp="$(dirname "$dir")/.$(basename "$dir").extracting"
rm -rf "$tmp"
mkdir -p "$tmp"
echo "== extracting $(basename "$deb") ($version)" >&2
dpkg -x "$deb" "$tmp"
printf '{\n  "name": "%s",\n  "version": "%s",\n  "deb_sha256": "%s"\n}\n' \
    "$package" "$version" "$sha" >"$tmp/photomat-source.json"
rmdir "$dir" 2>/dev/null || true
mv "$tmp" "$dir"
echo "$dir: $package $version"
