//! `view.html`: a self-contained page (WebGL, no network access) to turn and zoom a run's
//! curves over a sample of its points. The data are embedded as base64 float arrays, centred
//! and scaled to a unit box, so the page opens from the file system as it is.

use crate::crs::Crs;
use crate::curves::Polyline;
use crate::error::Result;
use base64::Engine;
use glam::DVec3;
use std::path::Path;

/// Points a view embeds at most: about 3 MB of base64.
pub(crate) const VIEW_POINTS: f64 = 250_000.0;

fn b64(bytes: &[u8]) -> String {
    base64::engine::general_purpose::STANDARD.encode(bytes)
}

/// Writes `view.html` at `path`: `points` (a sample) and `curves`, in world coordinates.
pub(crate) fn write_html(path: &Path, title: &str, points: &[DVec3], curves: &[Polyline], crs: &Crs) -> Result<()> {
    let mut b = crate::points::Bounds::EMPTY;
    points.iter().chain(curves.iter().flat_map(|c| c.vertices.iter().map(|v| &v.p))).for_each(|&p| b.grow(p));
    let (lo, hi) = if b.is_empty() { (DVec3::ZERO, DVec3::ONE) } else { (DVec3::from(b.min), DVec3::from(b.max)) };
    let centre = 0.5 * (lo + hi);
    let half = (0.5 * (hi - lo)).max_element().max(f64::MIN_POSITIVE);
    let unit = |p: DVec3| ((p - centre) / half).as_vec3().to_array();
    let pts: Vec<u8> = points.iter().flat_map(|&p| unit(p)).flat_map(f32::to_le_bytes).collect();
    let (mut lines, mut colours) = (Vec::new(), Vec::new());
    for c in curves {
        let rgb = crate::preview::curve_colour(c.id);
        for (a, b) in c.segments() {
            for p in [a, b] {
                lines.extend(unit(p).iter().flat_map(|x| x.to_le_bytes()));
                colours.extend_from_slice(&rgb);
            }
        }
    }
    let info = format!(
        "{title}: {} curves over {} points; extent {:.4} x {:.4} x {:.4}{}",
        curves.len(),
        points.len(),
        hi.x - lo.x,
        hi.y - lo.y,
        hi.z - lo.z,
        crs.units().map(|u| format!(" {u}")).unwrap_or_default()
    );
    let html = TEMPLATE
        .replace("@TITLE@", &html_escape(title))
        .replace("@INFO@", &html_escape(&info))
        .replace("@POINTS@", &b64(&pts))
        .replace("@LINES@", &b64(&lines))
        .replace("@COLOURS@", &b64(&colours));
    crate::workspace::write_atomic(path, html.as_bytes())
}

fn html_escape(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}

const TEMPLATE: &str = r#"<!doctype html>
<html><head><meta charset="utf-8"><title>crease: @TITLE@</title>
<style>html,body{margin:0;height:100%;overflow:hidden;background:#fff}canvas{width:100%;height:100%;display:block}
#info{position:absolute;left:8px;top:6px;font:13px sans-serif;color:#222;background:rgba(255,255,255,.75);padding:2px 4px}</style></head>
<body><canvas id="c"></canvas><div id="info">@INFO@<br>drag: turn &middot; shift-drag or right-drag: move &middot; wheel: zoom &middot; p: points on/off &middot; r: reset</div>
<script>
"use strict";
function dec(s, T) { const b = atob(s), u = new Uint8Array(b.length); for (let i = 0; i < b.length; i++) u[i] = b.charCodeAt(i); return new T(u.buffer); }
const pts = dec("@POINTS@", Float32Array), lin = dec("@LINES@", Float32Array), col = dec("@COLOURS@", Uint8Array);
const cv = document.getElementById("c");
const gl = cv.getContext("webgl", { antialias: true, preserveDrawingBuffer: true });
if (!gl) document.getElementById("info").textContent += " (WebGL is not available in this browser)";
function shader(t, s) { const o = gl.createShader(t); gl.shaderSource(o, s); gl.compileShader(o); return o; }
function program(vs, fs) { const p = gl.createProgram(); gl.attachShader(p, shader(gl.VERTEX_SHADER, vs)); gl.attachShader(p, shader(gl.FRAGMENT_SHADER, fs)); gl.linkProgram(p); return p; }
const pointProg = program("attribute vec3 p;uniform mat4 m;uniform float s;varying float h;void main(){gl_Position=m*vec4(p,1.);gl_PointSize=s;h=p.z;}",
  "precision mediump float;varying float h;uniform vec2 z;void main(){float t=clamp((h-z.x)/max(z.y-z.x,1e-6),0.,1.);gl_FragColor=vec4(vec3(.78-.4*t),1.);}");
const lineProg = program("attribute vec3 p;attribute vec3 c;uniform mat4 m;varying vec3 v;void main(){gl_Position=m*vec4(p,1.);gl_Position.z-=.003*gl_Position.w;v=c;}",
  "precision mediump float;varying vec3 v;void main(){gl_FragColor=vec4(v,1.);}");
function buffer(a) { const b = gl.createBuffer(); gl.bindBuffer(gl.ARRAY_BUFFER, b); gl.bufferData(gl.ARRAY_BUFFER, a, gl.STATIC_DRAW); return b; }
const pointBuf = buffer(pts), lineBuf = buffer(lin), colourBuf = buffer(col);
let zlo = 1e9, zhi = -1e9; for (let i = 2; i < pts.length; i += 3) { zlo = Math.min(zlo, pts[i]); zhi = Math.max(zhi, pts[i]); }
let yaw, pitch, dist, target, showPoints = true;
function reset() { yaw = -0.7; pitch = 0.55; dist = 3.2; target = [0, 0, 0]; }
reset();
const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const norm = a => { const l = Math.hypot(a[0], a[1], a[2]) || 1; return [a[0] / l, a[1] / l, a[2] / l]; };
function frame() {
  const eye = [target[0] + dist * Math.cos(pitch) * Math.sin(yaw), target[1] - dist * Math.cos(pitch) * Math.cos(yaw), target[2] + dist * Math.sin(pitch)];
  const f = norm(sub(target, eye)), s = norm(cross(f, [0, 0, 1])), u = cross(s, f);
  return { eye, f, s, u };
}
function matrix() {
  const { eye, f, s, u } = frame();
  const v = [s[0], u[0], -f[0], 0, s[1], u[1], -f[1], 0, s[2], u[2], -f[2], 0, -dot(s, eye), -dot(u, eye), dot(f, eye), 1];
  const a = cv.width / cv.height, t = 1 / Math.tan(0.35), n = dist * 0.01, far = dist * 10;
  const p = [t / a, 0, 0, 0, 0, t, 0, 0, 0, 0, (far + n) / (n - far), -1, 0, 0, 2 * far * n / (n - far), 0];
  const r = new Float32Array(16);
  for (let i = 0; i < 4; i++) for (let j = 0; j < 4; j++) { let x = 0; for (let k = 0; k < 4; k++) x += p[k * 4 + j] * v[i * 4 + k]; r[i * 4 + j] = x; }
  return r;
}
function attrib(prog, name, buf, size, type, normalized) { const l = gl.getAttribLocation(prog, name); gl.bindBuffer(gl.ARRAY_BUFFER, buf); gl.enableVertexAttribArray(l); gl.vertexAttribPointer(l, size, type, normalized, 0, 0); return l; }
function draw() {
  if (!gl) return;
  const w = cv.clientWidth * devicePixelRatio, h = cv.clientHeight * devicePixelRatio;
  if (cv.width !== w || cv.height !== h) { cv.width = w; cv.height = h; }
  gl.viewport(0, 0, cv.width, cv.height); gl.clearColor(1, 1, 1, 1); gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT); gl.enable(gl.DEPTH_TEST);
  const m = matrix();
  if (showPoints && pts.length) {
    gl.useProgram(pointProg);
    gl.uniformMatrix4fv(gl.getUniformLocation(pointProg, "m"), false, m);
    gl.uniform1f(gl.getUniformLocation(pointProg, "s"), 2 * devicePixelRatio);
    gl.uniform2f(gl.getUniformLocation(pointProg, "z"), zlo, zhi);
    const l = attrib(pointProg, "p", pointBuf, 3, gl.FLOAT, false);
    gl.drawArrays(gl.POINTS, 0, pts.length / 3); gl.disableVertexAttribArray(l);
  }
  if (lin.length) {
    gl.useProgram(lineProg);
    gl.uniformMatrix4fv(gl.getUniformLocation(lineProg, "m"), false, m);
    const a = attrib(lineProg, "p", lineBuf, 3, gl.FLOAT, false), b = attrib(lineProg, "c", colourBuf, 3, gl.UNSIGNED_BYTE, true);
    gl.drawArrays(gl.LINES, 0, lin.length / 3); gl.disableVertexAttribArray(a); gl.disableVertexAttribArray(b);
  }
}
let drag = null;
cv.addEventListener("contextmenu", e => e.preventDefault());
cv.addEventListener("mousedown", e => { drag = { x: e.clientX, y: e.clientY, move: e.shiftKey || e.button === 2 }; });
window.addEventListener("mouseup", () => { drag = null; });
window.addEventListener("mousemove", e => {
  if (!drag) return;
  const dx = e.clientX - drag.x, dy = e.clientY - drag.y; drag.x = e.clientX; drag.y = e.clientY;
  if (drag.move) { const { s, u } = frame(), k = dist / cv.clientHeight; target = [0, 1, 2].map(i => target[i] - k * (dx * s[i] - dy * u[i])); }
  else { yaw += dx * 0.01; pitch = Math.max(-1.55, Math.min(1.55, pitch + dy * 0.01)); }
  draw();
});
cv.addEventListener("wheel", e => { e.preventDefault(); dist *= Math.exp(e.deltaY * 0.001); draw(); }, { passive: false });
window.addEventListener("keydown", e => { if (e.key === "p") showPoints = !showPoints; if (e.key === "r") reset(); draw(); });
window.addEventListener("resize", draw);
draw();
</script></body></html>
"#;
