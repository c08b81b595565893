# Sourced by the depth-of-field bench scripts: the lens of the 1080p bench store's frames.
# The synthetic camera: fov 40 over 1080 rows, so raster x = a x/z + b with a = 540 / tan(20°).
# A point at depth z moves by a R (1/d - 1/z) for a lens point at radius R: focused on the
# nearest depth (d = 5), the far end (z = 50) moves by a R 0.18, and f-stop = focal length / 2R
# with focal length 1.
# lens_options RADIUS: the resample options of the lens whose circle of confusion at depth 50 has
# RADIUS pixels (0: --pinhole), one per line.
lens_options() {
  if [[ $1 == 0 ]]; then
    echo --pinhole
    return
  fi
  awk -v r="$1" 'BEGIN { a = 540 / (sin(20 * atan2(0, -1) / 180) / cos(20 * atan2(0, -1) / 180))
                         printf "--fstop\n%.6f\n--focal-length\n1\n--focus-distance\n5\n", 1 / (2 * r / (a * 0.18)) }'
}
