// ∫σ_t over the segment [a, b] inside the grid box, by 2-point Gauss–Legendre on the pieces
// between the points where the segment crosses cell-centre planes. σ_t of the trilinear
// medium is a cubic between crossings of any axis' planes, so with `every_axis` each piece
// is integrated exactly. Without it the segment is split at its dominant axis' planes only:
// about half the samples, and a piece that crosses another axis' plane has a kink there,
// whose error is second order in the lateral step (the sweep's short interpolated segments).

// The axis of v's largest component (the first on ties).
fn largest_axis(v: vec3f) -> u32 {
    var a = 0u;
    if v.y > v[a] {
        a = 1u;
    }
    if v.z > v[a] {
        a = 2u;
    }
    return a;
}

fn integrate_pieces(a: vec3f, b: vec3f, every_axis: bool) -> f32 {
    let len = length(b - a);
    let ua = (a - grid.min) / grid.cell - 0.5;
    let du = (b - a) / grid.cell;
    let adu = abs(du);
    let dominant = largest_axis(adu);
    var next = vec3f(2.0);
    var step = vec3f(0.0);
    for (var i = 0u; i < 3u; i++) {
        if i != dominant && !every_axis {
            continue;
        }
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
    let pieces = select(u32(adu[dominant]) + 4u, u32(adu.x) + u32(adu.y) + u32(adu.z) + 6u, every_axis);
    // Two pieces per iteration: the loop's own cost per iteration is about that of a sample.
    // A piece after the segment's end has h = 0 and adds nothing.
    for (var n = 0u; n < pieces; n += 2u) {
        let t1 = min(min(next.x, next.y), min(next.z, 1.0));
        next = select(next, next + step, next <= vec3f(t1));
        let t2 = min(min(next.x, next.y), min(next.z, 1.0));
        next = select(next, next + step, next <= vec3f(t2));
        let h1 = t1 - t0;
        let h2 = t2 - t1;
        let s1 = sigma_pair(ua + du * (t0 + 0.5 * h1), ua + du * (t0 + g0 * h1), ua + du * (t0 + g1 * h1));
        let s2 = sigma_pair(ua + du * (t1 + 0.5 * h2), ua + du * (t1 + g0 * h2), ua + du * (t1 + g1 * h2));
        acc += 0.5 * (h1 * (s1.x + s1.y) + h2 * (s2.x + s2.y));
        if t2 >= 1.0 {
            break;
        }
        t0 = t2;
    }
    return acc * len;
}
