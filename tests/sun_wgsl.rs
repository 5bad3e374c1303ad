//! Runs shaders/sun.wgsl on whatever adapter wgpu finds (a software one is enough) and checks
//! it against the exact f64 airlight. Skipped, with a message, where no adapter exists.

use fogsmith::reference::sun::{sun_la, FTable, GPU_TABLE_SIZE};
use std::f64::consts::PI;
use wgpu::util::DeviceExt;

const SHADER: &str = "
@group(0) @binding(0) var<storage, read> sun_table: array<f32>;
@group(0) @binding(1) var<storage, read> params: array<vec4f>;
@group(0) @binding(2) var<storage, read_write> out: array<f32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3u) {
    if (id.x >= arrayLength(&params)) {
        return;
    }
    let p = params[id.x];
    out[id.x] = sun_la(p.x, p.y, p.z, p.w, 1.0);
}
";

fn open_device() -> Option<(wgpu::Device, wgpu::Queue, String)> {
    let instance = wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle());
    let adapters = pollster::block_on(instance.enumerate_adapters(wgpu::Backends::all()));
    // Prefer non-GL backends: Mesa's GL path is the least trustworthy for compute.
    let adapter = adapters
        .into_iter()
        .filter(|a| a.get_downlevel_capabilities().flags.contains(wgpu::DownlevelFlags::COMPUTE_SHADERS))
        .max_by_key(|a| a.get_info().backend != wgpu::Backend::Gl)?;
    let name = format!("{} ({:?})", adapter.get_info().name, adapter.get_info().backend);
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor::default())).ok()?;
    Some((device, queue, name))
}

/// (γ, D_sv, D_vp, β): γ uniform in [0, π], T_sv in [0.1, 10], T_vp in [0.1, 50] or none.
fn parameters(n: usize) -> Vec<[f32; 4]> {
    let mut state = 0x0123_4567_u64;
    let mut next = move || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    (0..n)
        .map(|_| {
            let beta = 0.02 + next();
            let gamma = PI * next();
            let d_sv = 0.1 * 100f64.powf(next()) / beta;
            let d_vp = if next() < 0.25 { 1e30 } else { 0.1 * 500f64.powf(next()) / beta };
            [gamma as f32, d_sv as f32, d_vp as f32, beta as f32]
        })
        .collect()
}

#[test]
fn wgsl_airlight_matches_the_exact_formula() {
    let Some((device, queue, name)) = open_device() else {
        eprintln!("no wgpu adapter with compute shaders; skipping");
        return;
    };
    let table = FTable::remapped(GPU_TABLE_SIZE, GPU_TABLE_SIZE);
    let params = parameters(4096);
    let code = format!("{}\n{}", include_str!("../shaders/sun.wgsl"), SHADER);
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("sun test"),
        source: wgpu::ShaderSource::Wgsl(code.into()),
    });
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some("sun test"),
        layout: None,
        module: &module,
        entry_point: Some("main"),
        compilation_options: Default::default(),
        cache: None,
    });
    let storage = |label, contents: &[u8], usage| {
        device.create_buffer_init(&wgpu::util::BufferInitDescriptor { label: Some(label), contents, usage })
    };
    let table_buf = storage("table", bytemuck::cast_slice(&table.data), wgpu::BufferUsages::STORAGE);
    let param_buf = storage("params", bytemuck::cast_slice(&params), wgpu::BufferUsages::STORAGE);
    let size = (params.len() * 4) as u64;
    let out_buf = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("out"),
        size,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let staging = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("staging"),
        size,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("sun test"),
        layout: &pipeline.get_bind_group_layout(0),
        entries: &[
            wgpu::BindGroupEntry { binding: 0, resource: table_buf.as_entire_binding() },
            wgpu::BindGroupEntry { binding: 1, resource: param_buf.as_entire_binding() },
            wgpu::BindGroupEntry { binding: 2, resource: out_buf.as_entire_binding() },
        ],
    });
    let mut encoder = device.create_command_encoder(&Default::default());
    {
        let mut pass = encoder.begin_compute_pass(&Default::default());
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.dispatch_workgroups((params.len() as u32).div_ceil(64), 1, 1);
    }
    encoder.copy_buffer_to_buffer(&out_buf, 0, &staging, 0, size);
    queue.submit([encoder.finish()]);
    let (tx, rx) = std::sync::mpsc::channel();
    staging.map_async(wgpu::MapMode::Read, .., move |r| {
        let _ = tx.send(r);
    });
    device.poll(wgpu::PollType::wait_indefinitely()).expect("poll");
    rx.recv().expect("map callback").expect("map");
    let gpu: Vec<f32> = bytemuck::cast_slice(&staging.get_mapped_range(..).expect("mapped range")).to_vec();

    let (mut sum, mut max, mut worst) = (0.0, 0.0_f64, [0.0_f32; 4]);
    for (p, got) in params.iter().zip(&gpu) {
        let d_vp = if p[2] >= 1e30 { f64::INFINITY } else { p[2] as f64 };
        let exact = sun_la(p[0] as f64, p[1] as f64, d_vp, p[3] as f64, 1.0);
        let err = ((*got as f64 - exact) / exact).abs();
        assert!(got.is_finite(), "{p:?}: {got}");
        sum += err;
        if err > max {
            (max, worst) = (err, *p);
        }
    }
    println!("{name}: WGSL sun_la relative error mean {:.2e} max {max:.2e} at {worst:?}", sum / params.len() as f64);
    assert!(max < 0.003, "max relative error {max} at {worst:?}");
}
