#!/usr/bin/env bash
# Opens a run's curves with GDAL as a GIS user would (Debian's gdal-bin): curves.geojson with
# ogrinfo (feature count against report.json, the CRS GDAL sees against the run's), then
# converted to Shapefile, FlatGeobuf and GeoPackage with ogr2ogr (feature count, CRS and the
# per-curve fields kept), and the run's own curves.gpkg and curves.dxf when it wrote them
# (--format gpkg,dxf).
#
#   scripts/gis-check.sh RUN_DIR...        (runs made by `crease extract`)
#
# Prints one line per run and format; exits 1 if any check fails.
set -euo pipefail
command -v ogrinfo >/dev/null || { echo "needs GDAL's ogrinfo (apt-get install gdal-bin)"; exit 2; }
status=0
for run in "$@"; do
  if [ ! -f "$run/report.json" ]; then
    echo "FAIL $run: no report.json (not a finished run directory)"; status=1; continue
  fi
  curves=$(python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['counts']['curves'])" "$run/report.json")
  epsg=$(python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['crs']['epsg'] or '')" "$run/report.json")
  # Without a code, the CRS's name (the WKT's first quoted string) is what GDAL must show.
  name=$(python3 -c "import json,sys; w=json.load(open(sys.argv[1]))['crs']['wkt']; print(w.split('\"')[1] if w else '')" "$run/report.json")
  tmp=$(mktemp -d)
  formats=()
  # (The conversions start from curves.geojson; a run written without it is checked on the
  # formats it has.)
  [ -f "$run/curves.geojson" ] && formats=("GeoJSON:geojson" "ESRI Shapefile:shp" "FlatGeobuf:fgb" "GPKG:gpkg")
  # (A run written with --format gpkg: its own GeoPackage too.)
  [ -f "$run/curves.gpkg" ] && formats+=("native:curves.gpkg")
  for fmt in "${formats[@]+"${formats[@]}"}"; do
    driver=${fmt%%:*}; ext=${fmt##*:}
    src="$run/curves.geojson"
    if [ "$driver" = native ]; then
      src="$run/$ext"
    elif [ "$ext" != geojson ]; then
      ogr2ogr -f "$driver" "$tmp/curves.$ext" "$src" 2>/dev/null
      src="$tmp/curves.$ext"
    fi
    info=$(ogrinfo -so -al "$src" 2>/dev/null)
    count=$(grep -o 'Feature Count: [0-9]*' <<<"$info" | grep -o '[0-9]*$')
    # The layer's CRS as GDAL reads it: its root EPSG code (the last ID or AUTHORITY).
    seen=$(grep -oE '(ID\["EPSG",|AUTHORITY\["EPSG",")[0-9]+' <<<"$info" | tail -1 | grep -oE '[0-9]+$' || true)
    fields=$(grep -cE '^(id|closed|length|confidence|angle|shape|start|end|corners): ' <<<"$info" || true)
    gdal_name=$(sed -n '/Layer SRS WKT/{n;p;q}' <<<"$info" | cut -d'"' -f2)
    verdict=ok
    [ "$count" = "$curves" ] || verdict=FAIL
    if [ -n "$epsg" ]; then
      [ "$seen" = "$epsg" ] || verdict=FAIL
      crs="EPSG:${seen:-none} (run: EPSG:$epsg)"
    elif [ -n "$name" ]; then
      [ "$gdal_name" = "$name" ] || verdict=FAIL
      crs="\"$gdal_name\" (run: \"$name\", no code)"
    else
      # (A run without a CRS must not be read as WGS 84: GDAL should see an unknown local one,
      # or in a GeoPackage the standard's undefined Cartesian system, srs_id -1.)
      [ "$gdal_name" = unknown ] || [ "$gdal_name" = "Undefined Cartesian SRS" ] || verdict=FAIL
      crs="\"$gdal_name\" (run: none)"
    fi
    # (A run without curves has no fields to show; GeoPackage keeps the id as its FID.)
    want=9; [ "$ext" = gpkg ] && want=8; [ "$curves" = 0 ] && want=0
    [ "$fields" -ge "$want" ] || verdict=FAIL
    [ "$verdict" = ok ] || status=1
    printf '%-4s %-36s %-7s features %s/%s  fields %s  CRS %s\n' "$verdict" "$(basename "$run")" "$ext" "$count" "$curves" "$fields" "$crs"
  done
  # A run written with --format dxf: each curve as its typed pieces, a LINE, ARC, CIRCLE, SPLINE
  # or 3D POLYLINE on the layer of its kind, each with its curve's attributes as the CREASE
  # application's extended data (GDAL shows them as RawCodeValues); DXF has no CRS. The pieces
  # GDAL reads, by layer, are those of curves.json when the run wrote it too (--format json).
  if [ -f "$run/curves.dxf" ]; then
    info=$(ogrinfo --config DXF_INCLUDE_RAW_CODE_VALUES TRUE -al -q "$run/curves.dxf" 2>/dev/null)
    count() { grep -c "^  Layer (String) = crease_$1\$" <<<"$info" || true; }
    got="$(count lines) lines, $(count arcs) arcs, $(count circles) circles, $(count splines) splines, $(count curves) polylines"
    pieces=$(( $(count lines) + $(count arcs) + $(count circles) + $(count splines) + $(count curves) ))
    attributed=$(grep -c '^  RawCodeValues (StringList) = .*1001 CREASE,1000 id,' <<<"$info" || true)
    verdict=ok
    [ "$attributed" = "$pieces" ] || verdict=FAIL
    want=""
    if [ -f "$run/curves.json" ]; then
      want=$(python3 -c "
import json, sys
p = json.load(open(sys.argv[1]))['pieces']
n = lambda k: sum(1 for x in p if x['kind'] == k)
print(f\"{n('line')} lines, {n('arc')} arcs, {n('circle')} circles, {n('spline')} splines, {n('polyline')} polylines\")" "$run/curves.json")
      [ "$got" = "$want" ] || verdict=FAIL
    fi
    [ "$verdict" = ok ] || status=1
    printf '%-4s %-36s %-7s %s (curves.json: %s)  with attributes %s  CRS none (DXF has none)\n' "$verdict" "$(basename "$run")" dxf "$got" "${want:-not written}" "$attributed"
  fi
  rm -rf "$tmp"
done
exit $status
