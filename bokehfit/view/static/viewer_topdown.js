// viewer_topdown.js: the top-down sketch of the box beside the render: the camera, its field of
// view, the focus plane and the depth-of-field band, the scene and its reflection in the mirrors.

export class TopDown {
  constructor(canvas, config) {
    this.canvas = canvas;
    this.config = config;
    const cam = config.scene.camera;
    this.cam = cam;
    this.tanHalf = null;
    // Depth range shown: just behind the camera to the far end of the focus slider.
    this.depthMin = -0.12;
    this.depthMax = config.ranges.focus_distance_m[1] + 0.05;
    this.hover = null;
    const ratio = window.devicePixelRatio || 1;
    this.cssWidth = canvas.clientWidth || canvas.width;
    this.cssHeight = canvas.clientHeight || canvas.height;
    canvas.width = Math.round(this.cssWidth * ratio);
    canvas.height = Math.round(this.cssHeight * ratio);
    this.ratio = ratio;
    const margin = 28;
    this.scale = (this.cssHeight - 2 * margin) / (this.depthMax - this.depthMin);
    this.originX = this.cssWidth / 2;
    this.originY = this.cssHeight - margin + this.depthMin * this.scale;
  }

  // World point → (across, depth) in the camera's frame: across along `right`, depth along `forward`.
  project(p) {
    const c = this.cam;
    const d = [p[0] - c.position[0], p[1] - c.position[1], p[2] - c.position[2]];
    const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    return [dot(d, c.right), dot(d, c.forward)];
  }

  toScreen([across, depth]) {
    return [this.originX + across * this.scale, this.originY - depth * this.scale];
  }

  // Canvas position (CSS pixels) → depth along the view axis (metres).
  depthAt(y) {
    return (this.originY - y) / this.scale;
  }

  colour(name, alpha = 1) {
    const m = this.config.scene.materials[name];
    if (m.kind === "mirror") return `rgba(150, 190, 230, ${alpha})`;
    const [r, g, b] = m.colour.map((v) => Math.round(255 * Math.pow(Math.min(1, v), 1 / 2.2)));
    return `rgba(${r}, ${g}, ${b}, ${alpha})`;
  }

  // The scene's primitives, optionally reflected in the plane (o, n) (a mirror), drawn at `alpha`.
  drawScene(ctx, alpha, mirror) {
    const reflect = (p) => {
      if (!mirror) return p;
      const [o, n] = mirror;
      const t = 2 * ((p[0] - o[0]) * n[0] + (p[1] - o[1]) * n[1] + (p[2] - o[2]) * n[2]);
      return [p[0] - t * n[0], p[1] - t * n[1], p[2] - t * n[2]];
    };
    const pts = (corners) => corners.map((p) => this.toScreen(this.project(reflect(p))));
    const polygon = (ps) => {
      ctx.beginPath();
      ps.forEach(([x, y], i) => (i ? ctx.lineTo(x, y) : ctx.moveTo(x, y)));
      ctx.closePath();
    };
    const scene = this.config.scene;
    // Floor first (a fill), then the light (dashed: it hangs above), then walls, block, balls.
    for (const q of scene.quads) {
      const kind = scene.materials[q.material].kind;
      if (Math.abs(q.normal[1]) > 0.9 && q.normal[1] > 0 && kind !== "emitter") {
        polygon(pts(q.corners));
        ctx.fillStyle = this.colour(q.material, 0.12 * alpha);
        ctx.fill();
      }
    }
    for (const q of scene.quads) {
      const kind = scene.materials[q.material].kind;
      if (Math.abs(q.normal[1]) > 0.9) {
        if (kind === "emitter") {
          polygon(pts(q.corners));
          ctx.setLineDash([3, 3]);
          ctx.strokeStyle = `rgba(255, 220, 120, ${alpha})`;
          ctx.lineWidth = 1;
          ctx.stroke();
          ctx.setLineDash([]);
        }
        continue;
      }
      // A vertical quad is a segment from above: its two projected corners farthest apart.
      const ps = pts(q.corners);
      let best = [ps[0], ps[1]];
      let far = -1;
      for (let i = 0; i < 4; i++) {
        for (let j = i + 1; j < 4; j++) {
          const d = Math.hypot(ps[i][0] - ps[j][0], ps[i][1] - ps[j][1]);
          if (d > far) [far, best] = [d, [ps[i], ps[j]]];
        }
      }
      ctx.beginPath();
      ctx.moveTo(...best[0]);
      ctx.lineTo(...best[1]);
      ctx.strokeStyle = this.colour(q.material, alpha);
      ctx.lineWidth = kind === "mirror" ? 4 : 3;
      ctx.stroke();
    }
    for (const b of scene.boxes) {
      polygon(pts(b.corners));
      ctx.fillStyle = this.colour(b.material, 0.35 * alpha);
      ctx.fill();
      ctx.strokeStyle = this.colour(b.material, alpha);
      ctx.lineWidth = 1.5;
      ctx.stroke();
    }
    for (const s of scene.spheres) {
      const [x, y] = this.toScreen(this.project(reflect(s.center)));
      ctx.beginPath();
      ctx.arc(x, y, s.radius * this.scale, 0, 2 * Math.PI);
      ctx.fillStyle = this.colour(s.material, 0.35 * alpha);
      ctx.fill();
      ctx.strokeStyle = this.colour(s.material, alpha);
      ctx.lineWidth = 1.5;
      ctx.stroke();
    }
  }

  // Planar mirrors standing upright: the sketch shows the room's reflection beyond them.
  mirrors() {
    const scene = this.config.scene;
    return scene.quads
      .filter((q) => scene.materials[q.material].kind === "mirror" && Math.abs(q.normal[1]) < 1e-6)
      .map((q) => [q.corners[0], q.normal]);
  }

  draw(state, info) {
    const ctx = this.canvas.getContext("2d");
    ctx.setTransform(this.ratio, 0, 0, this.ratio, 0, 0);
    ctx.clearRect(0, 0, this.cssWidth, this.cssHeight);
    ctx.font = "11px system-ui, sans-serif";
    const tan = info ? info.values.tan_half[0] : 0.5;
    const wedgeX = (depth) => depth * tan * this.scale;
    const [cx, cy] = this.toScreen([0, 0]);
    const yAt = (depth) => this.originY - depth * this.scale;

    // Depth-of-field band inside the field of view.
    if (info) {
      const dof = info.depth_of_field;
      const near = dof.near_m;
      const far = dof.far_m === null ? this.depthMax : Math.min(dof.far_m, this.depthMax);
      ctx.beginPath();
      ctx.moveTo(cx - wedgeX(near), yAt(near));
      ctx.lineTo(cx + wedgeX(near), yAt(near));
      ctx.lineTo(cx + wedgeX(far), yAt(far));
      ctx.lineTo(cx - wedgeX(far), yAt(far));
      ctx.closePath();
      ctx.fillStyle = "rgba(120, 200, 120, 0.22)";
      ctx.fill();
    }

    for (const m of this.mirrors()) this.drawScene(ctx, 0.3, m);
    this.drawScene(ctx, 1, null);

    // Field of view.
    ctx.beginPath();
    ctx.moveTo(cx - wedgeX(this.depthMax), yAt(this.depthMax));
    ctx.lineTo(cx, cy);
    ctx.lineTo(cx + wedgeX(this.depthMax), yAt(this.depthMax));
    ctx.strokeStyle = "rgba(230, 230, 230, 0.55)";
    ctx.lineWidth = 1;
    ctx.setLineDash([5, 4]);
    ctx.stroke();
    ctx.setLineDash([]);

    // Camera: a small body behind the lens.
    ctx.fillStyle = "#e6e6e6";
    ctx.fillRect(cx - 9, cy, 18, 10);
    ctx.fillRect(cx - 5, cy - 4, 10, 4);

    // Near and far limits, and the focus plane.
    const line = (depth, style, width, label, dx = 4) => {
      if (depth > this.depthMax) return;
      ctx.beginPath();
      ctx.moveTo(cx - wedgeX(depth), yAt(depth));
      ctx.lineTo(cx + wedgeX(depth), yAt(depth));
      ctx.strokeStyle = style;
      ctx.lineWidth = width;
      ctx.stroke();
      if (label) {
        ctx.fillStyle = style;
        ctx.fillText(label, Math.min(cx + wedgeX(depth) + dx, this.cssWidth - ctx.measureText(label).width - 4), yAt(depth) - 4);
      }
    };
    if (info) {
      const dof = info.depth_of_field;
      line(dof.near_m, "rgba(120, 200, 120, 0.9)", 1, "");
      if (dof.far_m !== null) line(dof.far_m, "rgba(120, 200, 120, 0.9)", 1, "");
    }
    line(state.focus_distance_m, "#f0a640", 2, `focus ${state.focus_distance_m.toFixed(3)} m`);

    if (this.hover !== null) {
      line(this.hover, "rgba(240, 166, 64, 0.6)", 1, `${this.hover.toFixed(3)} m`);
    }

    // Legend.
    ctx.fillStyle = "#9aa0a6";
    ctx.fillText("top view · camera at the bottom", 8, 14);
    ctx.fillStyle = "rgba(150, 190, 230, 0.9)";
    ctx.fillText("beyond the mirror: its reflection", 8, 28);
  }
}
