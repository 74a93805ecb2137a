"""Every numeric tolerance used by the tests, in one place, each with its reason.

Tests import these as ``from tests.tolerances import NAME``. A tolerance is the size of an error
the test accepts; it is never a fudge factor that hides a wrong formula. Units are part of the
name (``_M`` metres, ``_PX`` pixels, ``_RAD`` radians, ``_DEG`` degrees) or the quantity is
dimensionless.
"""

from collections import namedtuple

# ----------------------------------------------------------------------------- round-off
# Dimensionless quantities of order 1 (unit vectors, sines, dot products, Snell invariants)
# computed with a handful of double-precision operations: eps = 2.2e-16, a few hundred ulps of
# headroom for cancellation (e.g. sqrt(1 - cos^2) near grazing incidence).
FLOAT64_UNIT = 1e-12

# Metres; double-precision round-off on geometry of millimetre to metre scale (port distances
# of 0.01-1 m, rays extended to a few hundred mm): 1 m * eps * a few hundred operations << 1e-12 m.
FLOAT64_GEOMETRY_M = 1e-12

# Radians; angles obtained by arcsin/arccos/atan2 of O(1) double-precision values. arccos loses
# precision near 0 (sqrt(eps) ~ 1.5e-8), so it is only used where the angle is far from 0.
FLOAT64_ANGLE_RAD = 1e-12

# Dimensionless Fresnel transmittance compared with the textbook angle form near grazing or
# critical incidence: cos(theta_t) = sqrt(1 - sin^2) is kept >= 1.4e-3 by the test, so an absolute
# round-off of 1e-16 in sin^2 becomes ~4e-14 / 2e-6 ~ 5e-11 relative in cos(theta_t) and in the
# reflectances; 1e-9 leaves a margin while a wrong polarisation term is off by > 1e-3.
FRESNEL_NEAR_GRAZING = 1e-9

# Degrees; the same round-off for angles converted to degrees (1e-12 rad * 57.3 deg/rad, rounded up).
FLOAT64_ANGLE_DEG = 1e-10

# Pixels; pixel coordinates up to ~1e4 px computed by a few multiply/divide steps from metres:
# 1e4 * eps * 100 operations ~ 2e-10 px, rounded up.
FLOAT64_PIXEL_PX = 1e-9

# Relative round-off for derived scalars (f-numbers, scales, focal lengths in px) that come from
# a few products and quotients of the parameters.
FLOAT64_RELATIVE = 1e-12

# ----------------------------------------------------------------------------- stated figures
# Degrees; docs/design.md quotes the reference port tilt as "about 26.6 deg" for the normal
# proportional to (0.0085, 0.5004, 1); the exact value is 26.58..., so the quoted figure is
# rounded to 0.1 deg and agrees within half of that.
QUOTED_TILT_DEG = 0.05

# Pixels per micro-image pitch; docs/design.md quotes "about 14.3 px per lens" for the Illum (the exact
# figure for its preset is 14.337): the quoted figure is rounded to 0.1 px.
QUOTED_PX_PER_LENS = 0.05

# Relative; docs/design.md quotes "about 541 x 434 microlenses" for the Illum (from Lytro metadata,
# whose MLA calibration differs slightly from the ideal preset lattice; the preset gives 539 x 433).
QUOTED_LENS_COUNT_RELATIVE = 0.01

# ----------------------------------------------------------------------------- discretisation
# Relative error of a second moment of a lens cell estimated on a midpoint grid of N x N unit-square
# samples (N = 300 in the test): the midpoint rule for a quadratic is off by 1 / (12 N^2) of the
# scale, i.e. ~1e-6 relative; 1e-4 leaves room while still failing for any wrong cell shape
# (hexagon vs square with the same pitch differ by 17 %, a hexagon of the wrong size by far more).
CELL_MOMENT_RELATIVE = 1e-4

# Fraction; share of samples that land in the inner, concentric half-size copy of the cell
# (exactly 1/4 for a uniform map). With a 300 x 300 midpoint grid the boundary of the inner cell
# cuts through ~3 * 300 samples out of 90000, so the count can be off by ~1e-2 at most; a
# non-uniform map (e.g. polar sampling, which puts 1/2 of the samples there) is off by 0.25.
CELL_INNER_FRACTION = 1e-2

# Fraction of pixels; the share of the tiny preset's pixels whose captured ray passes the main-lens
# aperture equals, analytically, (micro-image disc area) / (micro-image lattice cell area) = 0.7019.
# Counting pixel centres inside discs of radius 4.55 px whose centres fall at every sub-pixel phase
# (10.33 px pitch), plus partial micro-images along the sensor border (~5 % of the lenses), moves
# the count by a few 1e-3 (0.7035 measured). 0.01 still fails for a disc radius off by 0.7 % or a
# square instead of a hexagonal cell (0.608).
VIGNETTING_FRACTION = 1e-2

# ----------------------------------------------------------------------------- simulator
# Metres; the Dr.Jit sensor computes in float32 on millimetre-scale values (aperture radius ~1 mm,
# lens distances ~10 mm): eps32 * 10 mm * a few dozen operations ~ 3e-8 m (1.2e-8 measured).
SENSOR_VS_NUMPY_ORIGIN_M = 1e-7

# Dimensionless; float32 unit directions from a normalised slope vector (|slope| < 1): a few
# eps32 = 1.2e-7 per component (1.0e-7 measured).
SENSOR_VS_NUMPY_DIRECTION = 1e-6

# Pixels; intensity centroids of micro-images in a 64 spp white image of the tiny camera. The
# disc edge pixels are partially covered and estimated from 64 samples each, so the centroid
# carries Monte Carlo noise: 0.020 px RMS and 0.059 px worst case measured over ~1800 lenses.
MICRO_IMAGE_CENTRE_RMS_PX = 0.04
MICRO_IMAGE_CENTRE_MAX_PX = 0.15

# Pixels; the wrong model (micro-image centre straight below the lens centre) is off by
# c * f_mla / f' / pixel_pitch, up to 8 px at the tiny sensor's corners: a test that found centres
# within 2 px of it would have measured the wrong thing.
NAIVE_CENTRE_MIN_ERROR_PX = 2.0

# Pixels; intensity centroid of a fronto-parallel emissive disc (about 9 px across) in a 64 spp
# ideal image against the pinhole projection of its centre: the disc's image is an exact disc,
# anti-aliased by pixel-area integration; residual is MC noise on the ~60 edge pixels
# (0.004 px measured).
IDEAL_TARGET_CENTROID_PX = 0.02

# Pixels RMS; OpenCV corner detection with cornerSubPix on a 64 spp, 400 x 300 ideal image of a
# slanted chessboard with 16 x 16 texel squares (nearest-filtered) at ~13 px per square: the
# detector's bias on anti-aliased, perspective-distorted corners dominates (0.085 px RMS
# measured); a K or placement error of one pixel, or a flipped texture, fails by far.
IDEAL_CHESSBOARD_RMS_PX = 0.15

# Relative; depth from Mitsuba's float32 ray intersection, compared with the analytic plane:
# eps32 * a few operations.
DEPTH_FLOAT32_RELATIVE = 1e-5

# Fraction; raw pixels whose chief ray (traced through the port) lands well inside an emissive
# disc see its radiance times the port's transmittance: the mean ratio is 1 up to the neighbouring
# beam directions' slightly different Fresnel factors and MC noise. 0.9 still fails for any pixel
# set that the port trace mispredicts (those are dark).
RAW_TARGET_BRIGHT_MIN = 0.9

# Radiance; raw pixels whose chief ray misses the disc by more than the beam width see nothing but
# the black background.
RAW_TARGET_DARK_MAX = 1e-6

# Relative; median |raw / (L * T_fresnel * (n_air/n_water)^2) - 1| for pixels wholly inside their
# micro-image looking at a uniform emitter behind a 30 deg port. The pixel's paths span about 1 deg
# around its chief ray, over which T changes by < 0.1 %; no MC noise (constant radiance).
# Measured 1.1e-5 for both port models.
PORT_RADIANCE_RELATIVE = 1e-3

# Relative; median difference of per-micro-image mean radiance between the two port models at
# 16 spp (different integrators, so independent noise; textured scene, point lights). Each lens
# mean averages ~80 pixels x 16 samples of texture seen through a ~1 deg beam. Measured 0.0076
# (single interface) and 0.0093 (6 mm glass); a port tilted 5 deg less differs by 0.17.
PORT_MODELS_LENS_MEAN_RELATIVE = 0.015

# Dimensionless; the global mean radiance ratio of the two port models over all whole micro-images
# (~1800 lens means): noise averages down to 0.08 % measured.
PORT_MODELS_GLOBAL_MEAN_RELATIVE = 0.004

# Relative; the same per-lens comparison against a port tilted 5 deg less must differ by at least
# this (0.17 measured), or the comparison could not tell ports apart.
PORT_MODELS_WRONG_TILT_MIN = 0.05

# Metres; float32 port exit points of the sensor, on paths extended 15-25 mm from the lens:
# eps32 * 25 mm * a few dozen operations.
SENSOR_VS_NUMPY_PORT_POINT_M = 1e-6

# Relative; float32 Fresnel transmittance products from float32 cosines (a few eps32 each).
SENSOR_VS_NUMPY_WEIGHT_RELATIVE = 1e-5

# Metres and dimensionless; the Dr.Jit sensor's float32 trace through the 11 or 19 surfaces of a
# real lens against numpy's float64 trace (tiny and square-rotated-offset cameras, both presets,
# 20000 random paths): 2.1e-8 m and 5.8e-7 measured at most, the origins on front surfaces up to
# 63 mm from the axis origin. About 5 times the measured maxima.
SENSOR_VS_NUMPY_REAL_LENS_ORIGIN_M = 1e-7
SENSOR_VS_NUMPY_REAL_LENS_DIRECTION = 3e-6
# The same for the fisheye lens file (scenes/lenses/fisheye.toml, tests/simulator/test_lens_files.py):
# 17 surfaces, paths leaving at up to 90 deg, its front surface 0.18-0.22 m from the camera origin on
# the tiny and square-rotated-offset cameras. 20000 paths: origins 8.4e-8 m at most (3.5e-7 and 4.6e-7 of
# their distance from the origin, as the presets' 2.1e-8 m at 63 mm), directions 2.5e-6. Origins are
# checked relative to their distance (float32 round-off grows with it), 4 times the measured.
SENSOR_VS_NUMPY_LENS_FILE_ORIGIN_RELATIVE = 2e-6
SENSOR_VS_NUMPY_LENS_FILE_DIRECTION = 1e-5

# Pixels; projecting the pinhole sensor's float32 directions (1e-6) back with f = 321 px, plus the
# float32 film position ((u + 0.5) / W rounds to ~1e-5 px at W = 200).
SENSOR_VS_NUMPY_PIXEL_PX = 1e-3

# Radiance; white-image pixels wholly inside a micro-image: every path has weight 1 and carries
# radiance 1, accumulated in float32 over 64 samples (exact up to a few eps32).
WHITE_RADIANCE_ABS = 1e-6

# Relative; mean of the white image against (micro-image disc area) / (micro-image cell area):
# micro-images cut by the sensor border (~5 % of the lenses, partly compensating) move it by a
# few 1e-3.
WHITE_FILL_RELATIVE = 0.01

# Relative; flux (sum) of a luminous fronto-parallel disc in the ideal image against its projected
# area times radiance: exact under pixel-area integration up to MC noise on ~60 edge pixels at 64 spp.
IDEAL_DISC_FLUX_RELATIVE = 0.02

# Fraction; of the raw pixels that straight rays (ignoring the port) put on the luminous disc, at
# most this share may actually be lit (below 10 % of the disc's radiance would count as unlit):
# the port moves the disc's image by many micro-images, so a correct trace leaves them dark.
RAW_STRAIGHT_PREDICTION_MAX_LIT = 0.5
RAW_LIT_THRESHOLD = 0.1

# ----------------------------------------------------------------------------- procedural assets
# Values of order 0.01-0.1 m computed by one or two float64 operations: a few ulps (1.4e-17 at 0.1).
FLOAT64_FEW_OPS = 1e-15

# Band-pass (difference of box filters) std of the texture luminance that each scale must exceed.
# The texture gives about 0.03-0.05 at 2, 8 and 32 px; white noise gives 0.007 at 32 px, a 16 px
# Gaussian blur of it 0.0001 at 2 px, and a single octave 0.016 at 32 px.
TEXTURE_BAND_STD_MIN = 0.02

# Texels; OpenCV's detected chessboard corners against chessboard_inner_corners. cornerSubPix on a
# clean synthetic board is far better; half a texel still fails for any off-by-one-texel convention.
CORNER_TOL_TEXELS = 0.5

# Relative; mesh volume against the exact volume of the smooth bowl: the polygonal approximation
# loses about (2 pi / segments)^2 / 6 = 0.07 % around the axis plus the rim's and walls' chords; the
# defaults measure 0.1-0.2 % low. 1 % fails for a wall 2 % too thin or thick.
BOWL_VOLUME_RELATIVE = 0.01

# ----------------------------------------------------------------------------- synthesis
# Row sums of a warp map: float32 weights (eps 6e-8) summed over up to k * s^2 = 128 entries.
FLOAT32_WEIGHT_SUM = 1e-5

# The views' barycentric resampling (float64): weights may dip below 0 by the inside test's 100 eps
# and sum to 1 within a few eps; mixed over vertices up to 1e5 px from the origin (the test's far
# lenses) they reproduce a pixel's own coordinates to about 1e5 * 1e-16 * the triangle's condition.
RESAMPLING_WEIGHT_ROUNDOFF = 1e-12
RESAMPLING_REPRODUCTION_PX = 1e-6

# dB and SSIM; refraction-free synthesis (k = 32, s = 2, lambda = 0.3 m/rad) of the tiny camera
# against the ideal image inside the exact coverage, textured backdrop and chessboard, 32 spp,
# port 12 mm away, tilts 0 / 15 / 30 deg: measured PSNR 22.9 / 22.2 / 29.1 dB and SSIM 0.913 /
# 0.899 / 0.891. The residual is the light field's resolution (each output pixel averages rays
# from several microlenses) and MC noise, not geometry.
SYNTH_PSNR_DB = 20.0
SYNTH_SSIM = 0.85

# SSIM; the conventional central view (no refraction handling), gain-matched, in the same region:
# 0.013 / 0.104 / 0.149 measured; 0.3 separates it clearly from the synthesis.
NAIVE_SSIM_MAX = 0.3

# dB and SSIM; without refraction (equal indices) the synthesis over the whole image: 23.4 dB and
# 0.861 measured (the central view, also a central projection then, gives 22.6 dB, 0.841).
SYNTH_NO_PORT_PSNR_DB = 21.0
SYNTH_NO_PORT_SSIM = 0.82

# Pixels; phase-correlation shift between the synthesized and the ideal image in the exact region.
# Any systematic misalignment (wrong refraction, K or pixel convention) shows up as a shift; the
# conventional view is off by several pixels behind a 15 deg port (0.047 px and 7.1 px measured).
SYNTH_SHIFT_PX = 0.3

# Pixels RMS; chessboard corners (OpenCV findChessboardCornersSB refined by cornerSubPix) found in
# the synthesized image against the pinhole projection (K of the warp map's output) of the board's
# 3D corners: a slanted 7 x 5 board at ~9 px per square, 0.15 and 0.6 m away, behind a 0 and a
# 26.8 deg port (the tiny camera at twice its focal length and sensor, 16 spp, default options).
# Measured over seeds 0-2 (rim_margin_px = 1.0): 0.16-0.19 / 0.08-0.10 px at 0 deg (near / far),
# 0.30-0.33 / 0.14 px at 26.8 deg; seed 0 with the default 0.71 px margin: 0.17 / 0.09 and
# 0.23 / 0.11 px. The detector alone on the ideal image of the same scenes gives 0.10-0.13 px. The
# tilted near case carries a bias (0.2 px with a 1 px margin, under 0.05 px with none): the
# necessary rays cross the aperture well off-centre, so the +-2 px candidate window under each
# lens reaches the skipped rim pixels on its outer side only, and the k = 32 average leans towards
# the aperture centre (a fraction of a mm, which shifts the image as 1 / depth).
# 0.45 px still fails a half-pixel convention error (0.50-0.55 px at 0 deg) and a port tilt wrong
# by 1 deg (about 1 px in every case).
SYNTH_CORNER_RMS_PX = 0.45

# Pixels RMS; the same check on the conventional central view (no refraction handling) resampled
# onto the same K must miss by at least this: even at 0 deg the port magnifies the view by about
# n_water about the image centre (5.4-6.0 px measured), and the tilted port also shifts it
# (26-29 px).
NAIVE_CORNER_RMS_MIN_PX = 3.0

# Degrees and metres; port calibration (lfrefract.calibration.port) from ten synthetic views of a
# 9 x 6 board 0.2-0.5 m away with 0.05 px of corner noise (f = 600 px, port 30 mm, 10 mm glass):
# the accuracy (0.1 deg, 0.5 mm). Worst of four seeds: 0.045 / 0.036 / 0.008 deg and
# 0.54 / 0.14 / 0.02 mm at 0 / 15 / 30 deg of tilt (reported std 0.022 / 0.018 / 0.011 deg and
# 0.23 / 0.12 / 0.03 mm): an untilted port leaves its distance least determined.
PORT_CALIB_NORMAL_DEG = 0.1
PORT_CALIB_DISTANCE_M = 0.5e-3

# ----------------------------------------------------------------------------- MLA calibration
# Micro-image lattice from white images (lfrefract.calibration.mla). Rendered: the tiny camera
# (10.32-10.33 px micro-image pitch, 1613-1907 lenses) with the preset's hex MLA, a hex MLA rotated
# 0.1 rad and offset with f' = 6.2 mm, and a square MLA rotated -0.2 rad and offset; 64 spp, seeds
# 0-5. Synthetic: numpy discs (4 x 4 point samples per pixel, no noise) on a 200 x 150 px sensor
# with 8.2 px pitch.

# Pixels; fitted micro-image pitch against camera.micro_image_pitch_px: at most 8.3e-5 px measured
# (rendered) and 2.0e-4 px (synthetic, unrotated hex: there the sub-pixel phases of the discs repeat
# regularly, so their sampling errors do not average out). The lens lattice mistaken for the
# micro-image lattice would be off by 0.33 px.
MLA_PITCH_PX = 5e-4

# Radians; fitted lattice rotation: at most 4.5e-6 rad (rendered) and 4.9e-6 rad (synthetic).
MLA_ROTATION_RAD = 3e-5

# Pixels (micro-image px at the sensor); the implied MLA offset_m against the true lens lattice,
# modulo one lattice vector, scaled by micro_image_scale / pixel_pitch: at most 1.1e-3 px measured.
MLA_OFFSET_PX = 0.01

# Pixels; every fitted micro-image centre (the lattice) against camera.micro_image_centres_px: at
# most 0.0016 px RMS and 0.0031 px max measured. The lattice averages ~1800 centroids, so MC noise
# of one centroid (0.02 px) shrinks ~40-fold; the issue asked for 0.05 px. A half-pixel convention
# error or the lens-centre (not micro-image-centre) lattice fails by far.
MLA_FITTED_CENTRE_RMS_PX = 0.01
MLA_FITTED_CENTRE_MAX_PX = 0.02

# Pixels; the measured (re-centred window centroid) centre of each used micro-image against the
# truth: 0.021-0.024 px RMS and at most 0.076 px measured, MC noise on the partially covered edge
# pixels as in MICRO_IMAGE_CENTRE_RMS_PX, plus the pixel sampling of nearly touching discs.
MLA_MEASURED_CENTRE_RMS_PX = 0.04
MLA_MEASURED_CENTRE_MAX_PX = 0.15

# Pixels; synthetic (noise-free) images: fitted centres at most 0.0030 px off; measured centroids
# 0.024-0.032 px RMS. Their error is the point sampling of nearly touching discs (the discs come
# within a pixel of each other, so each window holds slivers of its neighbours): an aliasing error
# that differs from lens to lens.
MLA_SYNTHETIC_FITTED_MAX_PX = 0.01
MLA_SYNTHETIC_MEASURED_RMS_PX = 0.06

# Pixels; synthetic cat's-eye vignetting (a second stop 1.5 times the micro-image radius, shifted
# 0.03 times the distance from the axis) clips the outer discs and moves their centroids inwards by
# up to 0.69 px. With robust rejection the fitted centres stay within 0.081 px (0.048 px RMS)
# measured: discs clipped too little to stand out of the noise (under 6 sigma, ~0.14 px) still
# count. A plain least-squares fit through every disc is off by 0.30 px at the border.
MLA_VIGNETTED_FITTED_MAX_PX = 0.15
MLA_UNROBUST_MIN_ERROR_PX = 0.2

# Pixels RMS; a lattice stretched 1 % along v: the affine model fits it (centres within
# MLA_SYNTHETIC_FITTED_MAX_PX; 0.029 px RMS residuals, as unstretched), the regular model leaves
# 0.32 px RMS residuals measured.
MLA_AFFINE_REGULAR_MIN_RMS_PX = 0.1

# Pixels; fitted centres of the synthetic white blurred by a Gaussian of 1.2 px (soft edges: the gaps
# at 40 % of the centres): 0.0013 px max measured with windows re-centred until they settle. The
# fixed 3 re-centring steps of before left 0.0080 px (the window's pull on a soft disc shrinks only
# to two thirds a step). Blurred by 1.5 px (gaps at 60 % of the centres, refused before by a fixed
# gap ratio of 0.5): 0.0076 px max, the point sampling of discs that now overlap.
MLA_SOFT_WHITE_FITTED_MAX_PX = 0.003
MLA_SOFTER_WHITE_FITTED_MAX_PX = 0.015

# Pixels RMS; `detect_chessboard` on a synthetic board of 12 px squares, blurred 1.5 px, in an
# Illum-sized view whose 99th percentile clips the board's white at 0.24 of its level
# (tests/lfrefract/test_calibration_approx.py): refined on the linear image 0.04 px; refined on the
# clipped 8-bit image, as before the fix, 3.2 px. 0.3 px is about OpenCV's own corner error on
# blurred boards (0.2-0.4 px on the tiny views) and ten times below the clipped refinement's.
SMALL_BOARD_CORNER_RMS_PX = 0.3

# ----------------------------------------------------------------------------- approximation baseline
# Corner RMS (px) in the undistorted conventional image (tests/simulator/test_approx_baseline.py):
# the tiny-2x camera (188 x 141 px, f = 240 px), 16 spp, port 12 mm away with 4 mm glass, tilted
# 0 or 26.8 deg; `approx` calibrated from 6 board views at 0.2 m with their 3D corners known
# (pinhole at the camera centre); a slanted 7 x 5 test board at 0.2 m and at 0.6 m, off the axis.
# Measured over render seeds 0-2 (docs/calibration.md, "Approximation baseline").

# Pixels RMS; `approx` at its calibration depth: 0.16-0.20 px (0 deg) and 0.23-0.28 px (26.8 deg),
# mostly corner-detection noise in the central view (one sample per microlens: 0.3-0.5 px per
# corner at 16 spp against the exact refracted projection, 0.25-0.3 px at 64 spp). The same
# calibration without the known corners leaves the image in the fit's own frame, 20-32 px off.
APPROX_NEAR_RMS_PX = 0.5

# Ratio; `approx` at 0.6 m over `approx` at its 0.2 m calibration depth. Behind the 26.8 deg port
# 1.06-1.15 px against 0.23-0.28 px (4.0-4.9 x): the port's virtual centre of projection lies off
# the camera centre, so what the fit absorbs at 0.2 m (a shift of the image) is wrong elsewhere as
# 1 / depth. Behind the 0 deg port the growth is the radial term only (virtual centre on the axis):
# 0.39-0.43 against 0.16-0.20 px (2.0-2.4 x); the noise-free model predicts 0.01 -> 0.40 px there,
# and 0.11 -> 1.11 px tilted. A calibration that happened to be exact at every depth fails both.
APPROX_FAR_OVER_NEAR_TILTED_MIN = 2.0
APPROX_FAR_OVER_NEAR_STRAIGHT_MIN = 1.3

# Ratio; `approx` at 0.6 m behind the 26.8 deg port over the same behind the 0 deg port: 1.06-1.15
# against 0.39-0.43 px (2.5-2.9 x) measured; "the slanted port makes it worse" (paper section 3.1).
APPROX_TILTED_OVER_STRAIGHT_FAR_MIN = 1.5

# Synthetic calibration images (tests/lfrefract/test_calibration_approx.py): a 320 x 240 pinhole,
# f = 300 px, k1 = -0.25, k2 = 0.1, p1 = 0.002, p2 = -0.001; 8 views of a 7 x 5-corner board,
# 4 x 4 point samples per pixel, no noise. The detector is off by 0.05-0.12 px RMS per view there
# (aliasing of the sampled edges: 0.17 px at 2 x 2 samples), which bounds everything below.

# Pixels RMS; reprojection error of the fits: 0.094-0.097 px overall, at most 0.12 px per view.
APPROX_SYNTHETIC_RMS_PX = 0.2

# Relative; fitted focal lengths (0.65-0.68 % free, 0.02 % with known corners) and the board
# distances from the free fit's poses (0.69 %): the focal length trades off against the distance.
APPROX_SYNTHETIC_FOCAL_RELATIVE = 0.015

# Pixels; fitted principal point: 1.0 px off (free), 0.9 px (known corners, where it trades off
# against the rotation).
APPROX_SYNTHETIC_PRINCIPAL_PX = 3.0

# Dimensionless; k1, p1, p2: at most 0.011 off (k2 and k3 trade off: k2 0.28-0.48 off, not tested).
APPROX_SYNTHETIC_DIST_ABS = 0.03

# Degrees; the model's rotation (1 deg about x, 3 deg about y) from known corners: 0.22 deg off.
# The transposed rotation would be 6.3 deg off.
APPROX_SYNTHETIC_ROTATION_DEG = 0.5

# Pixels; known corners projected by the fitted model against the detected ones (0.19 px max), and
# corners found in an undistorted image against the output K's projection of the 3D corners
# (0.11 px RMS).
APPROX_SYNTHETIC_UNDISTORTED_PX = 0.3

# Ratio; the refraction-free image's corner error (tests/simulator/test_estimated_pipeline.py)
# with an MLA calibrated from a 16 spp white image and the port calibrated from ten 32 spp board
# captures (behind the 27 deg port), over the error with the true camera and port: issue 4's bound
# for the pipeline with estimated parameters. Measured 0.98-1.06 at 0.15 m, 0.92-1.0 at 0.6 m.
ESTIMATED_OVER_TRUE_CORNER_RMS = 1.5

# ----------------------------------------------------------------------------- light-field corners
# Pixels RMS; chessboard corners located on every raw pixel (lfrefract.calibration.corners) against
# the exact refracted projection, on raw images computed from the captured-ray model with a smooth
# chessboard texture (tests/lfrefract/test_corners.py; the tiny camera, 12 px squares): 0.006-0.010
# px measured at the main-lens centre, 0.006-0.011 px near the rim of the aperture. Not zero although
# the data are noiseless: the texture's blur is in board coordinates, which perspective makes
# asymmetric about the corner. The corner tracks across the aperture are held to twice this.
LF_CORNER_ANALYTIC_PX = 0.02

# Pixels RMS; the same on renders (tests/simulator/test_port_calibration_render.py: ten boards at
# 32 spp behind ports tilted 0 / 15 / 27 deg, tiny-2x camera): 0.019 / 0.019 / 0.023 px measured,
# where OpenCV's corners in the central view are 0.33-0.34 px off (GAIN: at least this many times
# the light-field error; 14-17 measured).
LF_CORNER_RENDER_PX = 0.04
LF_CORNER_RENDER_GAIN = 5.0

# Degrees and metres; the port calibrated from those corners. Issue 4 asks 0.1 deg and 0.5 mm.
# Measured at 0 / 15 / 27 deg (tilts (0, 0), (12, -9), (25, 10)): 0.046 / 0.144 / 0.064 deg and
# -1.52 / -0.49 / -0.36 mm (reported std 0.07 / 0.06 / 0.04 deg, 0.59 / 0.26 / 0.13 mm). An
# untilted port's distance is determined only by the departure of refraction from its paraxial
# form, which moves the corners by thousandths of a pixel per millimetre (docs/calibration.md).
PORT_RENDER_NORMAL_DEG = 0.2
PORT_RENDER_DISTANCE_M = 0.75e-3
PORT_RENDER_UNTILTED_DISTANCE_M = 2.5e-3

# ----------------------------------------------------------------------------- stereo
# lfrefract.stereo and the stereo metrics (tests/lfrefract/test_stereo.py, test_stereo_metrics.py).
# Synthetic data: a rig of two pinholes (320 x 240 px, f = 400 / 420 px, 0.12 m baseline, the
# right camera turned by 0.02 / -0.06 / 0.015 rad), smooth random textures (Gaussian-filtered
# uniform noise, sigma 2 px in the images), rectified pairs built from a known disparity field.

# Radians and metres; calibrate_stereo from noiseless corners of six views of a 9 x 6 board at
# 0.6-0.9 m: OpenCV takes the corners as float32 (0.5 ulp = 1.5e-5 px at 300 px), which limits the
# fit to 3.0e-8 rad and 2.4e-8 m measured over five board sets; the issue asked for ~1e-6.
STEREO_CALIB_ROTATION_RAD = 1e-6
STEREO_CALIB_TRANSLATION_M = 1e-6

# Pixels; the RMS reprojection error of that fit is the float32 rounding of the corners:
# 4.8e-6 to 5.5e-6 px measured. A left focal length 1 % off leaves 0.027 px (the board poses absorb
# most of it).
STEREO_CALIB_RMS_PX = 5e-5

# Pixels; the rectification maps (float32, values up to 320 px: ulp 3e-5 px) sampled bilinearly
# between pixel centres, against the exact rectifying homography: 6.1e-5 px measured (and
# 1.5e-5 px for the left map at pixel centres). Rows of corresponding points agree to 1.6e-13 px
# (FLOAT64_PIXEL_PX).
RECTIFY_MAP_PX = 5e-4

# Pixels RMS; ZNCC (9 px window, parabola refinement) on the slanted-plane pair
# d = 20 + 0.03 x + 0.02 y px: 0.067-0.072 px measured over six textures (0.070-0.074 px on the
# rectified rendered pair of the end-to-end test). The three-point parabola's own error
# dominates: even an exact integer shift gives 0.066 px, because the windowed ZNCC curve is not
# symmetric about its minimum. Integer disparities would give 0.29 px.
ZNCC_SLANTED_RMS_PX = 0.1

# Pixels; the largest single ZNCC error on that pair: 0.31-0.43 px measured (six textures).
ZNCC_MAX_ERROR_PX = 0.5

# Fraction of the matchable pixels (left window and the right windows of the neighbouring
# candidates inside the images) with a ZNCC estimate: 0.995 measured.
ZNCC_COMPLETENESS_MIN = 0.98

# Pixels RMS; the same pair without sub-pixel refinement must be at least this far off
# (0.291 px measured, 1/sqrt(12) = 0.289 for uniform rounding), or the refinement did nothing.
ZNCC_INTEGER_RMS_MIN_PX = 0.2

# Fractions of the 12 px band occluded in the right view (background at 12 px beside a
# foreground strip at 24 px): invalidated with the left-right check 0.80-0.91 measured over four
# texture pairs, without it 0.09-0.19 (only windows that lack a clear minimum drop out).
ZNCC_OCCLUDED_INVALID_MIN = 0.7
ZNCC_NO_CHECK_OCCLUDED_MAX = 0.4

# Pixels RMS and fraction; OpenCV SGBM (5 px blocks, 8-bit input) on the slanted pair: 0.13-0.19 px
# RMS with a few gross errors (up to 14 px), completeness 0.942 measured over six textures. Its
# integer matching cost and 1/16 px output are coarser than the ZNCC path.
SGBM_SLANTED_RMS_PX = 0.3
SGBM_COMPLETENESS_MIN = 0.9

# Fraction; left pixels whose true match lies in a NaN hole of the right image that SGBM leaves
# without estimate: 0.985-1.0 measured (ZNCC: all of them). The rest found a wrong partner just
# beside the hole that SGBM's left-right check let through.
SGBM_NAN_MATCH_INVALID_MIN = 0.95

# Degrees, metres, relative; end to end: both pinholes render a textured plane 0.9 m away tilted
# about 17 deg (point-sampled, 1 mm texels blurred 4 texels), the pair is rectified, matched by
# ZNCC, triangulated and the plane fitted by RANSAC. Measured over six textures: normal within
# 0.0005-0.0061 deg, offset within 0.023 mm; plane RMSE 1.02-1.07 mm, 0.97 times the depth noise
# predicted from the disparity RMS (Z^2 / (f B) * rms). A baseline 1 % off moves the offset by
# 9 mm; points left in the rectified frame (no R1.T) tilt the plane by 5.1 deg.
STEREO_PLANE_NORMAL_DEG = 0.05
STEREO_PLANE_OFFSET_M = 0.1e-3
STEREO_PLANE_RMSE_RELATIVE = 0.2

# Degrees, metres, relative, fractions; fit_plane_ransac on 1400 points of a 0.5 m square plane
# with 1 mm Gaussian noise along the normal plus 600 (30 %) uniform outliers in a 0.5 m cube,
# threshold 4 mm. Measured over eight seeds: normal within 0.027 deg (expected scatter
# sigma / (sqrt(N) * 0.14 m) = 0.011 deg), offset within 0.061 mm, inlier RMSE 0.995-1.023 times
# the noise (a 4-sigma band truncates by 0.1 %; the 4-9 outliers inside the band add up to 2 %),
# every true inlier kept, 0.7-1.5 % of the outliers kept (those in the band: 1.6 % expected).
RANSAC_NORMAL_DEG = 0.1
RANSAC_OFFSET_M = 0.2e-3
RANSAC_RMSE_RELATIVE = 0.05
RANSAC_INLIER_RECALL_MIN = 0.999
RANSAC_OUTLIERS_KEPT_MAX = 0.04

# ----------------------------------------------------------------------------- rigs
# Relative; a rendered rig's two depth maps (simulator/rig.py, the default rig: 6 cm baseline,
# 0.36-0.8 m): left surface points projected into the right camera against the right depth map
# at the nearest pixel, median over the points the right camera sees (86 % of them): 0.00045
# measured (the rounding to the nearest pixel). Swapped poses give 0.076, the left pose for both
# cameras 0.037.
RIG_DEPTH_AGREEMENT_RELATIVE = 0.01

# ----------------------------------------------------------------------------- averaging experiment
# simulator/experiments/averaging.py at scale tiny (default scene, tiny camera, 16 spp at seeds 0
# and 1, ideal image 2 x 1024 spp), measured inside the exact coverage (434 px). "Seed pairs": the
# same measures over raw seeds (0, 1), (2, 3), (4, 5) against ideal seeds 100 and 101.

# dB; PSNR at k = 8 above k = 64 (paper Fig. 9: 64 blurred): 1.97 dB measured (1.83 with one lamp
# sampled per sample, seed pairs 1.69-1.82).
AVERAGING_PSNR_GAIN_K8_DB = 1.0

# dB; PSNR at k = 8 above k = 1 (paper Fig. 9: 1 is noisy): 0.64 dB measured since every light is
# sampled (simulator/lighting.py; the render noise at k = 1 fell from about 20 % per pixel to 2.5 % of
# the data range), 1.65 dB before. Less noise leaves less for averaging to remove: PSNR now peaks at
# k = 4 (23.95 dB; k = 8: 23.85). Bound: half the measured gain.
AVERAGING_PSNR_GAIN_K8_OVER_K1_DB = 0.3

# SSIM at k = 8 above k = 64: 0.041 measured (0.038 before the lighting change).
AVERAGING_SSIM_GAIN_K8 = 0.02

# SSIM at k = 8 above k = 1: 0.010 measured since every light is sampled (0.039 before). Bound: half.
AVERAGING_SSIM_GAIN_K8_OVER_K1 = 0.005

# The k of the best PSNR: 4 measured (8 with one lamp sampled per sample); between these, the
# paper's "neither 1 nor 64".
AVERAGING_BEST_K_RANGE = (2, 16)

# Sharpness ratio (cross-seed gradient amplitude over the ideal image's); every k below this: 0.80 at
# most measured (k = 2; seed pairs up to 0.83): the light field samples once per microlens (about two
# output pixels), so even k = 1 is softer than the ideal image.
AVERAGING_SHARPNESS_MAX = 0.9

# Sharpness ratio drop from k = 8 to k = 64: 0.17 measured (0.78 -> 0.61; seed pairs 0.17-0.18).
AVERAGING_SHARPNESS_DROP_K64 = 0.1

# Sharpness ratio drop per doubling of k from k = 8 on: 0.032, 0.062, 0.076 measured (k = 1 to 8 is
# flat within 0.03, not asserted).
AVERAGING_SHARPNESS_STEP_MIN = 0.01

# dB; PSNR of the seed-independent error at k = 8 against k = 1 (averaging 8 nearby rays costs no
# structure): 0.06 dB apart measured (seed pairs 0.06-0.15).
AVERAGING_NOISE_FREE_PSNR_K8_VS_K1_DB = 0.5

# dB; PSNR of the seed-independent error lost from k = 8 to k = 64 (blur): 2.09 dB measured (seed
# pairs 2.05-2.11).
AVERAGING_NOISE_FREE_PSNR_LOSS_K64_DB = 1.0

# Relative; render noise at k over k = 1 against sqrt(raw pixels averaged at k = 1 / at k)
# (independent raw pixels; the 1/D weights are unequal, which would make the noise fall more slowly):
# within 3.6 % for every k measured (0.158 against 0.156 at k = 64).
AVERAGING_NOISE_SQRT_LAW_RELATIVE = 0.15

# Sharpness ratio, absolute; the cross-seed measure on a synthetic 128 x 128 texture (Gaussian noise
# blurred 1.5 px) with noise of half its std: 1.0 expected, 0.978 measured (0.98-1.02 over five
# seeds; the single-seed ratio reads 1.83); blurred by 1 px, 0.726 against the noise-free 0.706
# (within 0.034 over five seeds). Sampling error of 16 k pixel pairs.
AVERAGING_MEASURE_SHARPNESS = 0.05

# Relative; noise_rel of that texture, true 0.5: 0.503 measured (within 1 % over five seeds).
AVERAGING_MEASURE_NOISE_RELATIVE = 0.02

# dB; noise_free_psnr of the blurred noisy texture against the noise-free error's PSNR: 12.67 against
# 12.64 dB measured (within 0.41 dB over five seeds; with the noise it would read about 5.2 dB).
AVERAGING_MEASURE_PSNR_DB = 0.5

# ----------------------------------------------------------------------------- fov experiment
# simulator/experiments/fov.py at scale tiny (tiny camera, port 12 mm away, 4 mm glass, tilts 0-40 deg
# about x in 2.5 deg steps, f/2.2, 2.8, 4, 5.6).

# Pixels; exact_mask against build_warp_map(...).exact on the tiny camera (0, 15, 30 deg; 15 deg at
# f/4; 10 / -20 deg at f/2.8): 0 measured. Both evaluate the same floating-point expressions on the
# same sub-pixel rays, so any difference is a wrong mask, not round-off.
FOV_MASK_MISMATCH_MAX_PX = 0

# Fraction of the image; how much the exact share may rise from one tilt to a larger one: the exact
# cone keeps its angular size while tilt moves it off axis, where a pinhole image spends more pixels
# per steradian (1 / cos^3: +4.7 % at 10 deg). 0.0022 measured (f/5.6, 0.0536 at 5 deg to 0.0558 at
# 10 deg; f/4 0.0013; f/2.2 and f/2.8 never rise); falls to 0 by 40 deg at every f-number.
FOV_SHARE_RISE_MAX = 0.005

# Pixel angles (degrees of one pixel at the principal point); perfect_fov_h/v_deg of a pixel mask of a
# known cone (half angles 5-12 deg, on and 8 deg off axis) against its apex angle: the end pixels'
# centres lie up to one pixel inside the cone and their outer edges half a pixel beyond, so the
# bound is 1 px; up to 0.99 px measured.
FOV_RUN_PX = 1.0 + 1e-6

# Pixel angles; perfect_fov_equiv_deg (solid angle of the mask as a cone) of those masks: pixels cut
# by the cone's edge count whole or not at all, which averages out: up to 0.07 px measured.
FOV_EQUIV_CONE_PX = 0.5

# Pixel angles, below the apex angle only; perfect_cone_centred_deg of the centred masks: the nearest
# excluded pixel centre can lie one pixel beyond the cone along an axis and its square reaches half a
# pixel back, 1.5 px on each side: bound 3 px, 1.26-1.31 px measured.
FOV_CENTRED_CONE_PX = 3.0

# ----------------------------------------------------------------------------- planes experiment
# simulator/experiments/planes.py at the tiny scale (tests/simulator/test_experiment_planes.py).
# Ratio; the proposed method's plane-fit RMSE over the ideal images' at each depth (both at the raw's
# 16 spp). Measured 1.77 / 1.26 / 1.16 at 0.3 / 0.45 / 0.6 m with ZNCC, 1.05 / 0.94 / 0.91 with SGBM,
# since every light is sampled at every sample (simulator/lighting.py). Before, one of the two lamps
# per sample left about 20 % per-pixel noise in both; the synthesis averaged it away and came out at
# 0.90-0.93 of the ideal images, so issue 5's bound of 1.3 held. Without that noise what remains is
# the synthesis's own softness (k = 32 rays from neighbouring microlenses), which costs ZNCC most on
# the nearest, finest-textured plane. Bound 2.0: the measured worst with 13 % to spare.
PLANES_PROPOSED_OVER_IDEAL_RMSE = 2.0

# Relative to the depth; the proposed method's mean distance of the inlier points to the true
# plane: 1.9 / 2.4 / 2.7 mm measured with ZNCC (0.64 / 0.53 / 0.45 %), 1.2 / 1.7 / 2.7 with SGBM;
# the ideal images give 0.9 / 1.2 / 1.8 mm with ZNCC, the rest is the rig calibration (12 boards,
# 0.12 px RMS) and the matcher.
PLANES_PROPOSED_TRUTH_ERROR_RELATIVE = 0.01

# Ratio; the approximation calibrated at 0.3 m: its error at 0.6 m over its error at 0.3 m (7.1
# measured: 8.2 against 1.15 mm), and over the proposed method's at 0.6 m (3.0); with SGBM 9.1 and
# 3.9. Issue 5's bound.
PLANES_APPROX_GROWTH_MIN = 2.0

# Share of each method's plane points inside both cameras' exact coverage (the default rig's 20 deg
# wall, 15 mm away): 0.70-0.76 measured for the synthesized and approximated images, 0.50-0.53 for
# the ideal ones (they also cover the image's rim, outside the lenses' hull). Bounds: part in, part out.
PLANES_EXACT_SHARE_RANGE = (0.3, 0.95)
# Ratio; the proposed method's error against the true plane inside the exact coverage over that
# over all its points: 0.76-0.90 measured (both matchers, three depths). Outside the coverage the
# synthesis approximates, so the ratio cannot exceed 1 unless the coverage is computed wrong.
PLANES_EXACT_OVER_ALL_ERROR_MAX = 1.0

# ----------------------------------------------------------------------------- textured meshes
# Ratio; local colour contrast (mean absolute step between neighbouring pixels, per channel, over
# the mean) of the ideal image (tiny-2x, 32 spp) on a bowl and a figurine with texture_seed, over
# the same without: 2.0 measured (0.253 against 0.127; the plain objects' steps are mostly render
# noise and shading). Without the texture the ratio would be about 1.
TEXTURED_MESH_CONTRAST_GAIN_MIN = 1.5

# ----------------------------------------------------------------------------- objects experiment
# simulator/experiments/objects.py at the tiny scale (tests/simulator/test_experiment_objects.py):
# a textured bowl (0.31 m) and figurine (0.34 m) before a backdrop at 0.7 m, boards at 0.45 / 0.6 m.
# Fraction of the objects' pixels with a depth estimate, by matcher: ZNCC 0.70-0.76 measured for
# every method; SGBM 0.55-0.57 (its uniqueness and left-right checks drop more of the outlines
# and of the figurine's thin parts, and its mean and RMS errors are lower for it).
OBJECTS_COMPLETENESS_MIN = {"zncc": 0.6, "sgbm": 0.45}
# Ratio of median depth errors, the approximation calibrated at 0.6 m over the proposed method:
# 1.62 measured (3.31 against 2.04 mm; the ideal images give 1.41 mm); on the pixels inside both
# cameras' exact coverage (62 % of them) 2.04 (3.55 against 1.74 mm).
OBJECTS_APPROX_FAR_OVER_PROPOSED_MIN = 1.3

# ----------------------------------------------------------------------------- water
# [water] (tests/simulator/test_water.py).
# Absolute; Quan and Fry's (1995) index of sea water against tabulated values: Mobley (2010) after
# Austin and Halikas (1976), 0 and 35 psu, 0-30 C, 400-700 nm (5-decimal table): 5.8e-5 at worst
# measured, 2e-5 RMS (the equation's own fit error); Tilton and Taylor (1938), distilled water at
# 589.3 nm to four decimals: 2.3e-5 at worst. A wrong coefficient moves some value by 5e-4 or more.
WATER_INDEX_ABS = 1e-4

# Relative; Beer-Lambert on the tiny camera: rendered radiance, absorbing water over clear, against
# exp(-sigma_a * path) per quartile of path length and per channel (sigma_a = 2, 1, 0.5 per metre;
# path from the depth ground truth, plus the light leg for a point light). volpath estimates the
# transmittance by free-flight sampling (each sample passes or not), so the ratio carries binomial
# noise: worst 1.1 % measured for the ideal image (64 spp), 0.6 % for the raw image (16 spp, sensor and
# geometry port models). A missing medium (sensor, port face, shadow ray) is off by 20 % or more.
WATER_BEER_LAMBERT_RELATIVE = 0.03

# Relative; single-scattering veil of a lamp beside the camera in empty water (ideal image, 32 spp)
# against numerical quadrature of the single-scattering integral: 0.3-0.5 % measured for isotropic,
# Henyey-Greenstein g = 0.8 and RGB coefficients with g = 0.5. The noise of free-flight sampling.
WATER_VEIL_RELATIVE = 0.03

# ----------------------------------------------------------------------------- sub-aperture view stacks
# tests/lfrefract/test_view_stack.py: stacks at the default spacing of analytic raw images (chief ray of
# every pixel onto a fronto-parallel textured plane); each view's shift against the central view by ECC
# (lfrefract.metrics.shift_px), least-squares slope per axis over the grid against f_px * baseline / Z.
# Relative; that slope: tiny-2x 9 x 9 at 0.2 / 0.4 m (0.45 / 0.23 px per step) within 0.6 %, tiny with
# f' = 1.05 f, 5 x 5 at 0.1 m (0.47 px) within 2.2 % (seeds 0-3; 92 x 69 px views are what limits ECC).
# A baseline off by f' / f (5 %) fails it.
VIEW_STACK_DISPARITY_RELATIVE = 0.03
# Pixels; the largest distance of one view's measured shift from (-(c - h) d, -(r - h) d): 0.037 px
# measured on tiny-2x, 0.096 px on tiny (0.14 px on 9 x 9 tiny stacks): piecewise-linear interpolation
# between lens samples, one per two output pixels, pulls ECC towards the lens lattice.
VIEW_STACK_SHIFT_RESIDUAL_PX = 0.15

# Ratio; a calibrated camera's central view (its rays corrected) against the pinhole image of a
# textured plane, over the thin lens's own view of its own rays: MEASURED. The correction moves
# the lenses, so their interpolation samples the texture at other points.
VIEW_CALIBRATED_FLOOR_RATIO = 1.5

# ----------------------------------------------------------------------------- datasets
# Ratio; mean raw pixel of the default scene (tiny, 2 spp) in water with absorption_per_m = 1 over
# the same in clear water, both swept by a dataset (tests/simulator/test_dataset_run.py): 0.33
# measured. Light travels 0.8-1.7 m through the water to the backdrop and back (e^-0.8 to e^-1.7,
# 0.45 to 0.18); without the medium reaching the render the ratio would be 1 up to noise.
DATASET_TURBID_OVER_CLEAR_MAX = 0.6

# ----------------------------------------------------------------------------- sub-aperture view stacks (review)
# Fraction; darkening of the views of a default 9 x 9 stack against the central view on a uniform
# field (raw = 1 where the captured ray passes the aperture, else 0), tiny camera: the corner views'
# bilinear samples at the limit (micro-image radius less one pixel) give up to 7 % of their weight to
# pixels beyond the rim; 0.47 % measured (tiny), 0.50 % (tiny-2x, f01), every other view 0. A limit at
# the rim itself (no pixel margin) darkens the corners by half.
VIEW_STACK_CORNER_DARKENING_MAX = 0.01

# ----------------------------------------------------------------------------- port properties
# tests/lfrefract/test_port_properties.py and test_port.py (issue 12): random ports and rays,
# grazing ones included, through lfrefract.optics.port.FlatPort.

# Dimensionless; Snell's tangential invariant n (d - (d . n) n) of unit directions across one or
# two faces, indices up to N_MAX = 5. Each refraction keeps the tangential part to a few ulps of
# O(5) values (~1e-15); the glass direction, taken from the trace's entry and exit points, is used
# only where those points are at least 1e-5 of their own size apart (error < 1e-10). The issue's
# bound; an index off by 1e-6 or a ray out of the plane of incidence fails it.
PORT_SNELL_INVARIANT = 1e-9

# Relative to the largest point involved (metres), and absolute for unit directions: a ray traced
# out and back. Hit distances h / cos come from cosines with an absolute round-off of a few 1e-16,
# so their relative error is below ~1e-10 for cos >= GRAZING_COS_MIN = 1e-6 (a ray at cos 1e-6
# travels 1e6 gaps: only relative errors are meaningful). The bound.
PORT_REVERSAL_RELATIVE = 1e-9

# Relative; band around the critical angle, |n1 sin1 / n2 - 1|, in which the TIR flag is not
# asserted. Round-off of cos^2 = (1 - eta)(1 + eta) + (eta cos)^2 is ~25 eps = 6e-15 at eta = 5,
# and rays refracted into the glass within GRAZING_COS_MIN^2 / 2 = 5e-13 of the critical sine run
# along the face and are flagged misses instead; 1e-11 covers both with a margin of 20.
PORT_TIR_BAND = 1e-11

# Dimensionless; the reversal above is asserted only where the path is well conditioned:
# eps (n_max / n_min)^2 / c_min^2 <= this, c_min the smallest cosine along the path. Near the
# critical angle (and for rays grazing in the lighter medium, whose reverse is that case) a
# refracted cosine c_t inherits a relative error of eps (n1 / n2)^2 / c_t^2 from the rounding of
# the direction it is computed from, whatever the algorithm, and a point moves by that fraction
# of the distance travelled: measured 3e-6 of it for a 2.0 -> 1.0 refraction at c_t = 1e-5.
# 1e-10 keeps that ten times below PORT_REVERSAL_RELATIVE; elsewhere validity and finiteness
# are asserted.
PORT_REVERSAL_CONDITION = 1e-10

# ----------------------------------------------------------------------------- dataset memory
# Bytes; growth of the tracemalloc peak of building and checking every sample of a sweep one at a
# time (iter_samples) between 52 and 200 samples of the default scene, after a warm-up run. Only
# the sample being built is alive, so the peak is that of one sample (about 1.1 MB with the base
# scene's meshes) whatever the count; what varies is allocator noise and blocks parked on Python's
# free lists, measured at 35 kB between 100 and 400 samples (without the warm-up, free lists filling
# up added 340 kB). Holding every sample, as the earlier expansion did, costs about 12 kB per
# sample: 1.8 MB for the 148 extra samples.
DATASET_STREAM_PEAK_GROWTH_BYTES = 256 * 1024

# Bytes per sample; growth of the tracemalloc peak of a run's plan (one small record per sample:
# id, index, seed, swept values, hash, input paths) between 52 and 200 samples: measured 1.9 kB with
# two swept floats (the record's dicts, strings and the list holding them). 4 kB leaves room for
# longer swept values; the full samples that were held before cost about 12 kB each.
DATASET_PLAN_BYTES_PER_SAMPLE_MAX = 4 * 1024

# ----------------------------------------------------------------------------- hostile captures (issue 12)
# Fraction of output pixels; sub-aperture and naive views of a capture whose raw image has NaN in 3 %
# of its pixels, masked as unrecorded (--nonfinite mask): a view pixel has no value only where every
# raw pixel of its bilinear samples (up to 4 per lens, 3 lenses per pixel) is masked. Measured 0 on
# the tiny camera (0.06 % with half the pixels masked); spreading the NaN, as before, left 29-31 % of
# the central and sub-aperture views' pixels NaN and 99.5 % of the full-aperture view's.
MASKED_VIEW_EXTRA_NAN_FRACTION = 1e-3

# Seconds; refusing an image size beyond the limit or beyond the memory available is a few
# multiplications after reading the tiny camera's 0.7 MB raw image and its sidecar (measured
# 20-60 ms on a busy 2-core machine); before issue 12 these ran for minutes or allocated 71 GiB.
OVERSIZE_REFUSAL_SECONDS = 1.0

# Ratio of the tracemalloc peak to the estimate of lfrefract._memory (warp map) and lfrefract.synthesis.views
# (naive views, view stacks), on the tiny camera. An estimate may err high (it refuses work that would
# have fitted, by at most 1 / 0.4 = 2.5x) more than low (the work may then fail for memory, so by at
# most 25 %). Measured: warp maps 0.49-0.83 (analytic search) and 0.96-1.12 (k-d tree), naive views
# 0.46 (central) and 0.77 (full), view stacks 0.71-0.87. tracemalloc counts numpy's allocations, not
# numba's or qhull's (the views' Delaunay triangulation: 950 B per lens, which their estimates
# include). The depth-aware synthesis (whose accumulators numba allocates) is measured by the growth
# of the peak resident memory (VmHWM, reset before the work) instead: 0.59-0.70 on tiny-2x.
MEMORY_ESTIMATE_RATIO_MIN = 0.4
MEMORY_ESTIMATE_RATIO_MAX = 1.25

# Seconds; refusing a scene's mesh file (or a scene file) from its metadata alone: a 5 GiB sparse
# .obj is refused by os.stat before anything reads it (measured well under 10 ms, even with a busy
# 2-core machine); before issue 12 a 4 GB sparse OBJ was read by Mitsuba for 76 s before failing.
FILE_SIZE_REFUSAL_SECONDS = 1.0

# ----------------------------------------------------------------------------- direct lighting
# Relative per-pixel noise of the ideal image of a white plane lit by point lights, 8 spp
# (tests/simulator/test_lighting.py): with every light sampled at every sample, the only noise is
# where in the pixel a sample lands on the plane's smooth shading, 0.13-0.24 % measured with one or
# two lamps; 1 % leaves room for seeds and machines, while picking one of the two lamps at random
# per sample (Mitsuba's ``direct``) gives |L1 - L2| / (L1 + L2) / sqrt(spp), 19.6 % measured.
WHITE_PLANE_NOISE_RELATIVE = 0.01

# Largest difference between the image of two lights and the sum of the images of each light alone
# (same seed, same samples), relative to the image's brightest pixel: float32 sums of a few
# samples in another order, about 1e-7 of the value; 1e-5 leaves room for the accumulation over
# 2 spp. A random choice of one light per sample misses by a large fraction of the image.
LIGHT_SUPERPOSITION_RELATIVE = 1e-5

# ----------------------------------------------------------------------------- sensor model (issue 14)
# Standard errors; a flat field's sample mean of digital numbers per CFA channel (65536 to 131072
# pixels) against black + gain * mean electrons. The standard error is sqrt(variance / n), the
# theory's variance; 5 of them are exceeded by chance with probability 6e-7, while a missing or
# doubled shot-noise term, a wrong gain or a black level off by 1 DN moves the mean by far more.
DETECTOR_MEAN_STANDARD_ERRORS = 5.0

# Standard errors; the same flat field's sample variance against gain^2 (mean + read^2) + 1/12
# (Poisson shot noise, Gaussian read noise, rounding to integers). For nearly Gaussian samples the
# standard error of a variance is variance * sqrt(2 / (n - 1)): 0.39 % to 0.55 % here, so 5 of
# them are 2-3 %; leaving out the quantisation term (5.5 % of the variance in the low-gain case) or
# the read noise fails.
DETECTOR_VARIANCE_STANDARD_ERRORS = 5.0

# Dimensionless; a step edge blurred by the pixel-integrated Gaussian PSF against the closed form
# Phi((u - edge) / sigma): the kernel is cut at 6 sigma (2e-9 of the light) and renormalised, and
# the rest is double-precision round-off of sums of ~100 terms.
DETECTOR_GAUSSIAN_EDGE = 1e-8

# Dimensionless; the same step blurred by the Airy PSF (first dark ring 3 px) against the edge
# spread function integrated from the closed-form line spread function (4 / pi) H1(2 v) / v^2
# (Struve H1). The kernel stops at 25 ring radii, leaving out ~0.7 % of the light, and is
# renormalised, which moves the edge profile by up to 4e-3 (measured 2.8e-3); 8 sub-samples per
# pixel side integrate the core to ~1e-4. A Gaussian of the same 0.42 lambda N instead differs by
# 0.05 (it has no rings), an Airy PSF twice as wide by 0.14.
DETECTOR_AIRY_EDGE = 5e-3

# Pixels; 10-90 % width of a sampled profile 1 - Phi((r - R) / sigma) (0.01 px bins) against the
# exact 2.5631 sigma: linear interpolation between bins errs by < bin^2 / sigma ~ 1e-4 px.
DETECTOR_EDGE_WIDTH_PX = 1e-3

# Dimensionless; a flat colour through the tiny detector (64 frames averaged, shot noise ~1.5 % per
# frame, so 0.2 % per pixel after averaging and rounding to 1 DN of ~700), demosaiced and turned
# back into radiance by the inverse filter response and gain: the mean over the interior agrees
# within 0.5 % of the colour's largest channel; swapping R and B (a wrong OpenCV code) is off by
# 30 % or more.
DETECTOR_COLOUR_RELATIVE = 5e-3

# ----------------------------------------------------------------------------- main lenses
# tests/lfrefract/test_lens.py, against optiland's real-ray trace and first-order data.
# Issue 14's acceptance figures for agreement with an independent tracer (the tracers agree to about
# 1e-17 m and 1e-15 rad on these lenses; the margin covers other platforms' libm).
LENS_AGREE_POSITION_M = 1e-9
LENS_AGREE_DIRECTION_RAD = 1e-9
LENS_AGREE_FIRST_ORDER_RELATIVE = 1e-6
# Paraxial limit: rays 1e-6 f off the axis and 1e-6 rad off it. The thick lens departs from its
# first-order (thin-lens) mapping by third-order aberrations, (1e-6)^2 relative to the ray heights:
# measured 3e-12 on both presets (3e-8 at 1e-4, as the square predicts). 1e-10 leaves a margin, while
# a principal plane misplaced by 1 nm already moves the heights by 1e-7 of themselves.
LENS_PARAXIAL_RELATIVE = 1e-10

# Relative; a rendered Lytro capture (tiny camera, tiny sensor, 16 spp) developed with the white image
# of its setting (8 frames) against the noiseless raw.exr, per colour, the median ratio inside the
# micro-images: 1.010 / 1.015 / 1.014 (R, G, B) measured after the file's colour matrix (without
# it, 1.000 / 1.000 / 1.043: the filters' cross-talk between colours). Not devignetted, the same
# capture reads 0.67-0.68 (the white level's scale) with the micro-images' fall-off.
LYTRO_DEVELOPED_RATIO = 0.06

# Relative to the mean; the refraction-free image synthesized from that LFR capture against the one
# from raw.exr, RMS over the exact coverage: 0.050 measured at 16 spp, 0.048 at 64 spp (shot and read
# noise, and the demosaicing, which mixes each pixel with its neighbours); 0.49 not devignetted.
LYTRO_SYNTH_RELATIVE_RMS = 0.1

# Real lenslet white images (napari-LF's microscope examples, tests/lfrefract/test_real_whites.py).
# Relative; the fitted pitch against the nominal lenslet pitch over pixel size: GUVExperim1 +0.10 %,
# antleg +0.34 %, seaurchin +1.8 % measured (its metadata gives a 7.4 um pixel; relay optics change
# the effective one, as the antleg README says of its own). A wrong lattice is off by 30 % or more.
REAL_WHITE_NOMINAL_PITCH_RELATIVE = 0.03
# Relative; GUVExperim1, whose metadata states its optics, alone: +0.10 % measured.
REAL_WHITE_PITCH_RELATIVE = 0.003
# Pixels; centroids about the regular lattice: 0.134 / 0.259 / 0.187 px RMS measured (a real MLA's
# lenses off a perfect lattice, anisotropy and the flat field's own structure), against 0.02-0.05 px
# on rendered whites.
REAL_WHITE_RMS_PX = 0.35
# Pixels; GUVExperim1 about the affine lattice: 0.030 px RMS measured (regular: 0.134 px).
REAL_WHITE_AFFINE_RMS_PX = 0.06

# The camera's ray model from in-air chessboard light fields (tests/simulator/test_camera_calibration.py,
# tiny-2x camera, ten boards at 0.15-0.35 m, 16 spp). Double Gauss: the corners' distance to their
# rays 0.093 mm RMS on the thin-lens model, 0.058 mm calibrated (0.62 of it); the calibrated rays'
# angle to the true rays 2.28 -> 0.86 mrad RMS (0.38 of it). The bounds leave a margin for noise.
CAMERA_CAL_RMS_GAIN = 0.8
CAMERA_CAL_ANGLE_GAIN = 0.5
# A thin-lens camera: the correction is the identity to the corners' noise: pupil and slope scales
# 1.0004 and 1.0010, k1 0.0007 measured (ten boards; standard deviations 0.0004, 0.0005, 0.002).
CAMERA_CAL_THIN_SCALE = 0.005
CAMERA_CAL_THIN_K1 = 0.02
# The refraction-free image's corners through the double Gauss behind a port tilted (25, 10) deg, a
# board at 0.6 m: 0.313 px RMS from their true projection with the thin-lens warp map, 0.160 px with
# the calibrated one (0.51 of it; the thin lens's own 0.108 px).
CAMERA_CAL_CORNER_GAIN = 0.7
# The port behind (25, 10) deg calibrated from underwater boards through the double Gauss: normal
# 1.575 deg off on the thin-lens model, 0.457 deg on the calibrated one (0.29 of it).
CAMERA_CAL_PORT_NORMAL_GAIN = 0.5
# The data-only chain from Lytro files (tests/simulator/test_data_only_chain.py: double Gauss, tiny
# sensor model, 32 spp, port (25, 10) deg): corners of the refraction-free image 1.579 / 1.418 px RMS
# (0.15 / 0.6 m) on the thin-lens chain, 0.724 / 0.640 px on the calibrated one (0.46 / 0.45 of it);
# the port normal 0.90 -> 0.51 deg off.
DATA_ONLY_CORNER_GAIN = 0.7

# The pipeline experiment at tiny scale (double Gauss, tiny sensor, the default rig's 20 deg wall;
# tests/simulator/test_pipeline_experiment.py). Measured: oracle (thin lens, true camera and port,
# noiseless) corners 0.133 px, plane RMSE 1.24 mm, error against the true plane 2.46 mm; data-only
# (MLA, camera and port calibrated from the Lytro files: twenty in-air and twenty port boards, both
# rings, 8 frames averaged; the ray model refined with the port; partly lit pixels left out of the
# board fits) 0.138 px, 1.81 mm, 2.61 mm (1.04x, 1.46x, 1.06x); thin-lens-assumed 2.41 px, 2.12 mm,
# 6.55 mm (2026-12-06; 0.151 px, 1.84 mm, 2.86 mm on the k-d tree's maps, 2026-12-05). The bound is 1.5x
# the oracle's, for the corners and the plane measures alike (the plane RMSE has the least margin: it
# was 1.46x before the refinement, whose gain is in the port and the corners; 1.54x with the unlit
# pixels of the rig's captures masked in the synthesis, a change not made). The corners are also held
# to a third of the thin-lens chain's. The same bounds hold against the true-rays chain (the real
# captures synthesized with the double Gauss traced and the true port, the oracle of a real-lens
# capture): it measured 0.172 px, 2.03 mm, 3.94 mm, so data-only stands at 0.77x, 0.89x, 0.56x of it
# (2026-12-07; the calibration fitted on the images does better than the lens's true chief rays).
# Since the pixels a Lytro capture's white does not light are unrecorded (they were read as 0, black
# samples: through the Heliar design the rig's stereo failed on them) data-only measures 0.132 px,
# 1.894 mm, 2.428 mm: 0.77x, 0.93x, 0.62x the true rays', 0.99x, 1.53x, 0.99x the thin-lens oracle's.
# The plane fit's RMSE is held to the true rays' alone: against the thin-lens oracle it also carries the
# real lens's image formation (the true rays' own plane RMSE is 1.64x the thin-lens oracle's).
PIPELINE_PLANE_RATIO = 1.5
PIPELINE_CORNER_RATIO = 1.5
PIPELINE_CORNER_GAIN = 1.0 / 3.0
# The data-only port's normal against the truth: 0.166 deg measured (0.134 deg with every lit pixel in
# the board fits, 0.107 deg on the in-air ray model alone before the board reading's changes;
# thin-lens-assumed 2.25 deg; 0.23 deg with the inner ring of boards alone and one frame each).
PIPELINE_PORT_NORMAL_DEG = 0.25

# Squares; how far inside the view every inner corner of a calibration board lies (simulator.boards'
# port and in-air boards, both rings; tests/simulator/test_board_layouts.py). The outer ring's closest
# corners are 6.3-7.7 px (0.45-0.55 of a 14 px square) inside; OpenCV finds every such board in the
# pipeline's renders. At 2x the inner ring's offsets instead of 1.6x the boards leave the view.
BOARD_CORNER_MARGIN_SQUARES = 0.4

# ----------------------------------------------------------------------------- HCI benchmark scores
# Dimensionless (relative); tests/lfrefract/test_hci_metrics.py compares MSE x 100 and BadPix
# percentages with figures worked out by hand. Its disparities and errors are powers of two or
# short sums of them, so every difference, square and sum is exact; what is left is the division
# by the pixel count and the factor 100, two correctly rounded operations (1.1e-16 relative each).
# 1e-12 leaves room for another summation order, while one pixel more or less in a count of 20
# moves a score by 5 %.
HCI_SCORE_RELATIVE = 1e-12

# ----------------------------------------------------------------------------- dataset images
# Relative to a value's magnitude; a 16-bit PNG float image decodes to float32, which rounds
# ``offset + code * scale`` by half an ulp (2**-24 relative), on top of the half code step the
# encoding itself allows (checked separately).
PNG16_DECODE_FLOAT32_RELATIVE = 2.0**-24

# ----------------------------------------------------------------------------- ground-truth labels
# simulator.groundtruth.surface_labels and raw_pixel_truth (tests/simulator/test_groundtruth_labels.py),
# against numpy ray/plane intersections. Mitsuba intersects in float32.
# Dimensionless, per component of a unit normal: Mitsuba builds a rectangle's or disk's normal from
# its float32 to_world matrix and normalises it in float32 (a few eps32 = 1.2e-7 per component);
# the rotation into the camera frame is float64. A normal left in the world frame, or rotated by R
# instead of R^T, is off by more than 0.1 under the tests' pose. 5.6e-8 measured.
LABEL_NORMAL_FLOAT32 = 1e-5

# Relative; camera-frame z of the first hit along a raw pixel's ray. Mitsuba takes the ray in
# float32 (origin on the port's water face or the lens's front, plus the pose's 0.27 m shift:
# 3e-8 m; direction to eps32 = 6e-8) and returns a float32 distance t: a few eps32 of the
# 0.3-0.6 m distance, amplified by the planes' slant (incidence up to 56 deg, 1 / cos = 1.8): ~1e-6
# relative (2.8e-7 measured), as the ideal image's depth (DEPTH_FLOAT32_RELATIVE). A ray left
# unrefracted by the port misses by more than 1e-3 relative (the test checks that it would).
RAW_DEPTH_FLOAT32_RELATIVE = 1e-5

# Relative to the distance along the ray; pixels whose ray passes this close to an object's rim are
# left out of the exact comparison of instance ids and of hit / no hit: Mitsuba's float32 ray moves
# the hit point by a few eps32 (6e-8) of its distance, so it may decide either way there. 1e-5
# leaves out well under 3 % of the pixels (the test checks it).
LABEL_EDGE_MARGIN_RELATIVE = 1e-5

# ----------------------------------------------------------------------------- forward projection
# Forward projection through a flat port (lfrefract/optics/forward.py; tests/lfrefract/test_forward_projection.py).
# Metres; the backward trace (FlatPort.trace_from_air) of the air ray the solver returns must pass this close
# to the point (ports tilted up to 40 deg, 5-60 mm away, 0 or 2-8 mm of glass; points 0.05-3 m away). The
# solver stops at a lateral residual of 1e-12 m (DEFAULT_TOLERANCE_M); the trace adds float64 round-off of a
# few 1e-16 m per metre travelled, amplified by 1 / cos^2 of the incidence: 1.0e-12 m worst measured over
# 48 000 points. A wrong index or Snell term misses by millimetres.
FORWARD_MISS_M = 1e-9
# Radians; a point placed on a traced water-side ray (0.05-3 m beyond the port) gives the air ray back to
# about the solver's residual over the path's length, 1e-12 m / 0.05 m = 2e-11 rad (5.7e-12 measured over
# 6 000 rays). A ray one Snell term off differs by > 1e-3 rad.
FORWARD_DIRECTION_RAD = 1e-10
# Radians; Agrawal et al.'s quartic for a single interface, solved as the eigenvalues of 4 x 4 companion
# matrices, against the iteration: the eigenvalues carry eps times the polynomial's conditioning (1.7e-11
# measured over 20 000 points); the wrong root of the quartic is off by degrees.
FORWARD_QUARTIC_RAD = 1e-9
# Iterations; Newton's method from the left on the concave residual converges quadratically from the
# first step: 9 measured for 48 000 random points. More than 15 would mean the bisection safeguard is doing
# the work (60 halvings to converge).
FORWARD_SOLVER_ITERATIONS_MAX = 15

# ----------------------------------------------------------------------------- view-stack disparity truth
# simulator/view_truth.py; tests/simulator/test_view_truth.py.
# Relative; the traced disparity against its analytic value (in air f b / Z; behind a port the float64
# oracle's displacement of the analytic plane's point) or against the same map in another view: the surface
# point lies at Mitsuba's float32 hit distance (relative error a few 1e-8 to 1e-7, as DEPTH_FLOAT32_RELATIVE),
# which moves the disparity by as much relative, and the maps are stored in float32 (6e-8). 2.5e-7 measured
# (tiny camera, planes at 0.3-0.5 m, no port and ports tilted 0 and (25, 10) deg). A baseline or focal length
# off by one part in 1e4, or the neighbour on the wrong side, fails by far.
VIEW_TRUTH_RELATIVE = 2e-6
# Relative; behind a port parallel to the lens, the disparity of the pixels half a pixel off the axis (the
# tiny view's cx is 45.5) against the paraxial apparent-depth value f b / (d + t n_a / n_g + w n_a / n_w): the
# field angle 0.5 / 120 rad changes the refraction's lateral magnification by ~T^2 (1 - n_a^2 / n^2) 3 / 2 ~ 1e-5
# relative (2.1e-5 measured). The in-air value (a wrong sign of refraction) is 30 % away, the edge 10 %.
VIEW_TRUTH_PARAXIAL_RELATIVE = 1e-4
# Metres; pixels whose float64 oracle ray meets the plane this close to its rectangle's edge may fall on
# either side in Mitsuba's float32 geometry (rounding of a 0.3 m hit point: ~3e-8 m); the NaN-mask comparison
# leaves them out (at most 2 of 6348 pixels, asserted). Pixels are ~2 mm apart on the plane.
VIEW_TRUTH_EDGE_M = 1e-6

# ----------------------------------------------------------------------------- pixels seeing points
# lfrefract/optics/seen_by.py; tests/lfrefract/test_seen_by.py.
# Metres; the exact path of the raw-pixel position found for a point and an aperture point, traced back out
# by the camera (rays_through_lenses with the MLA offset) and the port (FlatPort.trace_from_air), must pass
# this close to the point (tiny camera, a port 2 cm away tilted (12, -8) deg with 5 mm of glass, points
# 0.2-1 m away). The air ray is forward_project's, which passes within FORWARD_MISS_M; the pixel round trip
# adds float64 round-off on the 6 mm lens / 0.2 mm MLA geometry, magnified by the object-to-sensor
# magnification (~1 m / 6 mm ~ 170): 9.6e-13 m worst measured with the port (the solver's 1e-12 m residual),
# 4.5e-16 m without (2000 pairs each). A wrong thin-lens or microlens
# term moves the ray by millimetres (one microlens, 0.1 mm on the MLA, is ~15 mm at 1 m).
SEEN_BY_MISS_M = 1e-9

# ----------------------------------------------------------------------------- depth-aware synthesis
# tests/lfrefract/test_depth_aware.py: tiny-2x behind a port 40 mm away tilted 26.8 deg, raw values
# in closed form (each ray's texture value on the plane it meets; a texture of 0.1-0.9 with periods
# of 14-20 px), pixels MARGIN_PX from the field's border and from depth edges.

# Relative depth error counted as right, and the share of pixels that must be right. Measured on
# the plane at 0.5 m: 100 % within 1 % (median -0.75 mm); 1 % of 0.5 m is a parallax of 0.09 px
# between the aperture's edges on tiny-2x, the sub-step refinement's reach. Beside an occluding
# edge (0.3 m in front of 0.6 m), farther from it than MARGIN_PX: 99.9 %.
DEPTH_AWARE_DEPTH_RELATIVE = 0.01
DEPTH_AWARE_DEPTH_SHARE = 0.95

# Share of the depths within MARGIN_PX of that edge that lie outside the range between its two
# surfaces (by more than DEPTH_AWARE_DEPTH_RELATIVE). Measured 2.4 %; 10.0 % before each pixel's say
# in the aggregation was bounded (the curves of pixels mixing both surfaces then pulled the
# background to about 1.2 m); the bound is what the test guards, so it sits at 5 %.
DEPTH_AWARE_EDGE_OUTLIER_SHARE = 0.05

# RMS error of the rendered values against the texture (values 0.1-0.9), given the true depth and
# given the estimated one. Measured 0.0022 and 0.0022: the texture's curvature within a pixel,
# which the per-pixel plane fit leaves. A ray landing half a pixel off would cost ~0.09 (the
# texture's slope, up to 0.18 per pixel), the stand-in rays of the warp map cost 0.15 there.
DEPTH_AWARE_TRUE_DEPTH_RMSE = 0.005
DEPTH_AWARE_GIVEN_DEPTH_RMSE = 0.005

# The same estimator with the rays continued straight through the port: the plane at 0.5 m appears
# at 0.378 m (its apparent depth, about z / n_water), 24 % off. A refraction-unaware result within
# 15 % would mean the port has no effect on the sweep.
NO_REFRACTION_DEPTH_ERROR_MIN = 0.15

# experiment fov, given_depth_share: over every 2nd pixel in each direction on the tiny scale, so a
# share can differ from the whole image's by the sampling (an exact region of 100 pixels along its
# edge changes a 6348-pixel share by about 0.5 %). Measured against every pixel at 0, 15, 30 and
# 40 deg: 0.2-0.5 %.
FOV_SEEN_SHARE_SAMPLING = 0.01
# The recorded share (seven aperture points) against the pixels the depth-aware synthesis renders
# exact or exact given depth on a closed-form plane at that depth (min_rays rays or more). Measured
# at 0 / 15 / 30 / 40 deg: 56.3 / 55.7 / 44.4 / 35.3 % recorded, 57.2 / 56.5 / 45.7 / 38.0 % rendered
# (a pixel's rays land anywhere in its square, the test looks along its centre only).
FOV_SEEN_SHARE_RENDERED = 0.05

# The joint refinement of ray model and port (tests/lfrefract/test_joint_calibration.py): exact
# synthetic views through a known correction and port (15 mm, tilted (20, -3) deg), the in-air
# estimate off by 1-1.3 of its standard deviations in pupil scale and drift. The port on the in-air
# model alone: 0.30 deg / 0.34 mm off; refined with the camera: 0.018 deg / 0.002 mm (0.02 px corner
# noise). The bounds leave a margin of about 5 over the refined errors and are well below the
# sequential ones, so a refinement that does nothing fails.
JOINT_NORMAL_DEG = 0.1
JOINT_DISTANCE_M = 0.05e-3
# The held-back check of that refinement: each board's corners predicted by fits without it, RMS
# over 6 boards x 350 residuals (about 1.5 % sampling error), pose refitted. Refined: 1.03 times the
# noise (0.02 px image noise times n_air / n_water); on the in-air model 1.84 times. The factor leaves
# the refined side a margin of 0.12 and the in-air side one of 0.5.
HELD_BACK_NOISE_FACTOR = 1.15
# Synthetic board light fields of a camera with field curvature (tests/lfrefract/test_calibrate_camera.py):
# the mean of the fitted boards' centre depths over their true ones, less 1. Small boards with the slope
# scale held: 0.6 % measured (fitted freely, as before it could be held: 2.7 %, each board 2.1-3.5 % too
# far); large boards: under 0.2 %.
CAMERA_CAL_BOARD_DEPTH_RELATIVE = 0.015
# The slope scale fitted from large synthetic boards against the synthetic camera's (1.0): the field
# curvature the model lacks biases it a little; 1 % is the spread the calibration accepts (MAX_SCALE_STD).
CAMERA_CAL_FREE_SLOPE_SCALE = 0.01
# The generic polynomial ray model (tests/lfrefract/test_polynomial_rays.py). Its inverse (Newton on the
# four thin-lens coordinates) to 1e-12 of the aperture and field scales: 1e-12 m leaves ample room.
POLY_INVERSE_M = 1e-12
# Noise-free boards seen along a (3, 1) model: the fit returns it to rounding (its frame kept): 1e-9 m
# 25 mm out (measured about 1e-13 m).
POLY_NOISE_FREE_RAY_M = 1e-9
# The synthetic field-curvature camera, polynomial model chosen among symmetric-3, symmetric-5 and the
# generic (5, 1): symmetric-5, 0.0008 mm and 0.025 mrad measured (radial model: 0.045 mm, 0.39 mrad);
# the bounds fail the radial model and a choice of the generic (5, 1) (0.0085 mm, 0.077 mrad).
POLY_SYNTHETIC_RAY_M = 0.005e-3
POLY_SYNTHETIC_ANGLE_RAD = 0.1e-3
# The lens-family chain without rendering (tests/simulator/test_lens_family_calibration.py: the nine
# lenses, seed 0, 0.05 px of corner noise): the calibrated rays' RMS distance (m) and angle (rad) from
# the true ones at the port face, the port normal's error (deg) and distance's (m), by camera.
# At the Illum's pitch the targets (measured, seeds 0 and 1: rays 0.003-0.018 mm and 0.02-0.18
# mrad, normal 0.001-0.054 deg, distance 0.002-0.25 mm). At tiny-2x, where ten boards leave the normal
# 0.04-0.18 deg uncertain, about twice the worst of seeds 0 and 1: rays up to 0.116 mm and 0.58 mrad
# (double Gauss and fisheye, symmetric-3 chosen), normal up to 0.159 deg, distance up to 1.21 mm.
LensFamilyBounds = namedtuple("LensFamilyBounds", "ray_m ray_rad normal_deg distance_m")
LENS_FAMILY_BOUNDS = {
    "illum": LensFamilyBounds(ray_m=0.05e-3, ray_rad=1e-3, normal_deg=0.1, distance_m=1e-3),
    "tiny-2x": LensFamilyBounds(ray_m=0.25e-3, ray_rad=1.2e-3, normal_deg=0.35, distance_m=2.5e-3),
}

# ----------------------------------------------------------------------------- port calibration advice
# The port's standard deviations the advice predicts with its views against those the refitted port
# states with them (tests/lfrefract/test_port_advice.py: four frontal boards plus three advised; with a
# camera model, seeds 1-5: ratios 0.87-1.44 for the normal, 0.98-1.54 for the distance). The advice
# takes the boards' noise inflated as the calibration's capture-clustered covariance was over its pixel
# noise's, by the largest ratio over directions (1.0-3.5 from four captures), so it errs high.
ADVICE_PREDICTION_FACTOR = 2.0
# The camera model's part of them: linear in the boards, predicted at the calibrated port and refitted
# at the new one (0.2-0.3 deg apart); measured ratios 1.00-1.19 over seeds 1-5. Held fixed (as if no
# board reduced it) it would be 3-7 times the refit's.
ADVICE_MODEL_PART_FACTOR = 1.25
# The lens-family truth in a calibration's frame against the simulator's true rays moved to the
# paraxial entrance pupil (tests/simulator/test_lens_family_calibration.py, the retrofocus design at
# tiny-2x, a degree-(5, 3) fit, 0.3 of the aperture), RMS at the port face: measured 0.16 um; a fit
# with the frame's coefficient dropped instead of the rays moved was 6.9 um off (64 um over the whole
# aperture).
LENS_FAMILY_FRAME_M = 1e-6
# ... and their slopes, which a move leaves alone: the two fits differ by up to 3e-6 (their least
# squares weigh the rays' origins differently).
LENS_FAMILY_FRAME_SLOPE = 1e-5
