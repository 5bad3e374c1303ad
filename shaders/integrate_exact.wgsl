// ∫σ_t over a segment inside the grid box, exact for the trilinear medium: the directional
// sweep's short steps (the point-light sweep has its own cheaper variant). σ_t is a cubic
// between the points where the segment crosses cell-centre planes of any axis, and 2-point
// Gauss–Legendre integrates each such piece exactly.

fn integrate_pieces(a: vec3f, b: vec3f) -> f32 {
    let len = length(b - a);
    let ua = (a - grid.min) / grid.cell - 0.5;
    let du = (b - a) / grid.cell;
    var next = vec3f(2.0);
    var step = vec3f(0.0);
    for (var i = 0u; i < 3u; i++) {
        if du[i] > 1e-6 {
            next[i] = (floor(ua[i]) + 1.0 - ua[i]) / du[i];
            step[i] = 1.0 / du[i];
        } else if du[i] < -1e-6 {
            next[i] = (ceil(ua[i]) - 1.0 - ua[i]) / du[i];
            step[i] = -1.0 / du[i];
        }
    }
    let g0 = 0.21132487;
    let g1 = 0.78867513;
    var acc = 0.0;
    var t0 = 0.0;
    let pieces = u32(abs(du.x) + abs(du.y) + abs(du.z)) + 4u;
    for (var n = 0u; n < pieces; n++) {
        let t1 = min(min(next.x, next.y), min(next.z, 1.0));
        let h = t1 - t0;
        if h > 0.0 {
            let s = sigma_pair(ua + du * (t0 + 0.5 * h), ua + du * (t0 + g0 * h), ua + du * (t0 + g1 * h));
            acc += 0.5 * h * (s.x + s.y);
        }
        if t1 >= 1.0 {
            break;
        }
        t0 = t1;
        next = select(next, next + step, next <= vec3f(t1));
    }
    return acc * len;
}
