//! [`GpuMesh`] and [`GpuObject`]: a mesh's vertex buffers and an object's transform.

use super::*;
/// A mesh's vertex and index buffers.
pub struct GpuMesh {
    /// Interleaved vertices (see the shader's `VertexIn`).
    pub vertices: wgpu::Buffer,
    /// `u32` triangle list.
    pub indices: wgpu::Buffer,
    /// Index count.
    pub index_count: u32,
}

impl GpuMesh {
    /// Uploads `mesh`; `depths`, when given, is each vertex's depth below the polygon (for
    /// `displaced` geometry), else 0. The curvature attribute is 0 (flat): see
    /// [`GpuMesh::with_curvature`].
    #[must_use]
    pub fn new(ctx: &GpuContext, mesh: &Mesh, depths: Option<&[f32]>) -> Self {
        Self::with_curvature(ctx, mesh, depths, None)
    }

    /// [`GpuMesh::new`] with each vertex's curvature form for silhouettes
    /// (`pomkit_core::silhouette::vertex_curvature` of the mesh as drawn in the world; rotation
    /// and uniform scale leave it unchanged).
    #[must_use]
    pub fn with_curvature(ctx: &GpuContext, mesh: &Mesh, depths: Option<&[f32]>, curvature: Option<&[Vec3]>) -> Self {
        let mut data = Vec::with_capacity(mesh.positions.len() * VERTEX_FLOATS);
        for i in 0..mesh.positions.len() {
            let (p, n, t, uv, s) =
                (mesh.positions[i], mesh.normals[i], mesh.tangents[i], mesh.uvs[i], mesh.uv_scale[i]);
            let d = depths.and_then(|d| d.get(i)).copied().unwrap_or(0.0);
            let k = curvature.and_then(|k| k.get(i)).copied().unwrap_or(Vec3::ZERO);
            data.extend_from_slice(&[
                p.x, p.y, p.z, n.x, n.y, n.z, t.x, t.y, t.z, t.w, uv.x, uv.y, s.x, s.y, d, k.x, k.y, k.z,
            ]);
        }
        let bytes: Vec<u8> = data.iter().flat_map(|x| x.to_le_bytes()).collect();
        let vertices = ctx.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("pomkit vertices"),
            contents: &bytes,
            usage: wgpu::BufferUsages::VERTEX,
        });
        let ibytes: Vec<u8> = mesh.indices.iter().flat_map(|x| x.to_le_bytes()).collect();
        let indices = ctx.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("pomkit indices"),
            contents: &ibytes,
            usage: wgpu::BufferUsages::INDEX,
        });
        Self { vertices, indices, index_count: mesh.indices.len() as u32 }
    }
}

/// An object's model matrix (bind group 2).
///
/// A model matrix with a mirror (negative determinant) is drawn right: the shader flips the
/// tangents' handedness, and the pipeline must take the opposite winding as the front, because
/// the mirror reverses every triangle on screen: build it with
/// `PipelineOptions { front_face: object.front_face(wgpu::FrontFace::Ccw), .. }`.
pub struct GpuObject {
    /// The bind group to set at index 2.
    pub bind_group: wgpu::BindGroup,
    buffer: wgpu::Buffer,
    mirrored: std::sync::atomic::AtomicBool,
}

impl GpuObject {
    /// An object with the model matrix `model`.
    #[must_use]
    pub fn new(ctx: &GpuContext, pipelines: &MaterialPipelines, model: Mat4) -> Self {
        let buffer = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("pomkit object"),
            size: 128,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let bind_group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("pomkit object"),
            layout: &pipelines.object_layout,
            entries: &[wgpu::BindGroupEntry { binding: 0, resource: buffer.as_entire_binding() }],
        });
        let o = Self { bind_group, buffer, mirrored: std::sync::atomic::AtomicBool::new(false) };
        o.set_model(ctx, model);
        o
    }

    /// Sets the model matrix (normals use its cofactor matrix, sign-corrected for mirrors). The
    /// last element of the normal matrix carries the determinant's sign, which flips the
    /// tangents' handedness `w` under a mirror, as `Mesh::transformed` does on the CPU.
    pub fn set_model(&self, ctx: &GpuContext, model: Mat4) {
        let m = Mat3::from_mat4(model);
        let (c0, c1, c2) = (m.x_axis, m.y_axis, m.z_axis);
        let cof = Mat3::from_cols(c1.cross(c2), c2.cross(c0), c0.cross(c1));
        let mirrored = m.determinant() < 0.0;
        let cof = if mirrored { -cof } else { cof };
        let mut normal_matrix = Mat4::from_mat3(cof);
        normal_matrix.w_axis.w = if mirrored { -1.0 } else { 1.0 };
        self.mirrored.store(mirrored, std::sync::atomic::Ordering::Relaxed);
        let mut u = Std140::new();
        u.mat4(model).mat4(normal_matrix);
        ctx.queue.write_buffer(&self.buffer, 0, &u.bytes());
    }

    /// Whether the model matrix mirrors (its determinant is negative).
    #[must_use]
    pub fn is_mirrored(&self) -> bool {
        self.mirrored.load(std::sync::atomic::Ordering::Relaxed)
    }

    /// The winding of front faces for this object in a pipeline whose meshes have `front` as
    /// theirs: the opposite one when the model matrix mirrors (see [`GpuObject`]).
    #[must_use]
    pub fn front_face(&self, front: wgpu::FrontFace) -> wgpu::FrontFace {
        match (self.is_mirrored(), front) {
            (false, f) => f,
            (true, wgpu::FrontFace::Ccw) => wgpu::FrontFace::Cw,
            (true, wgpu::FrontFace::Cw) => wgpu::FrontFace::Ccw,
        }
    }
}
