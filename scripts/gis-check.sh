#!/usr/bin/env bash
# Opens a run's curves with GDAL as a GIS user would (Debian's gdal-bin): curves.geojson with
# ogrinfo (feature count against report.json, the CRS GDAL sees against the run's), then
# converted to Shapefile, FlatGeobuf and GeoPackage with ogr2ogr (feature count, CRS and the
# per-curve fields kept).
#
#   scripts/gis-check.sh RUN_DIR...        (runs made by `crease extract`)
#
# Prints one line per run and format; exits 1 if any check fails.
set -euo pipefail
command -v ogrinfo >/dev/null || { echo "needs GDAL's ogrinfo (apt-get install gdal-bin)"; exit 2; }
status=0
for run in "$@"; do
  curves=$(python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['counts']['curves'])" "$run/report.json")
  epsg=$(python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['crs']['epsg'] or '')" "$run/report.json")
  tmp=$(mktemp -d)
  for fmt in "GeoJSON:geojson" "ESRI Shapefile:shp" "FlatGeobuf:fgb" "GPKG:gpkg"; do
    driver=${fmt%%:*}; ext=${fmt##*:}
    src="$run/curves.geojson"
    if [ "$ext" != geojson ]; then
      ogr2ogr -f "$driver" "$tmp/curves.$ext" "$src" 2>/dev/null
      src="$tmp/curves.$ext"
    fi
    info=$(ogrinfo -so -al "$src" 2>/dev/null)
    count=$(grep -o 'Feature Count: [0-9]*' <<<"$info" | grep -o '[0-9]*$')
    # The layer's CRS as GDAL reads it: its root EPSG code (the last ID or AUTHORITY).
    seen=$(grep -oE '(ID\["EPSG",|AUTHORITY\["EPSG",")[0-9]+' <<<"$info" | tail -1 | grep -oE '[0-9]+$' || true)
    fields=$(grep -cE '^(id|closed|length|confidence|angle|start|end|corners): ' <<<"$info" || true)
    verdict=ok
    [ "$count" = "$curves" ] || verdict=FAIL
    if [ -n "$epsg" ]; then [ "$seen" = "$epsg" ] || verdict=FAIL; fi
    # (Shapefile keeps the id as its FID, not as a field.)
    want=8; [ "$ext" = shp ] && want=7; [ "$ext" = gpkg ] && want=7
    [ "$fields" -ge "$want" ] || verdict=FAIL
    [ "$verdict" = ok ] || status=1
    printf '%-6s %-40s %-8s features %s/%s  CRS EPSG:%s (run: %s)  fields %s\n' "$verdict" "$run" "$ext" "$count" "$curves" "${seen:-none}" "${epsg:-no code, WKT only}" "$fields"
  done
  rm -rf "$tmp"
done
exit $status
