// A traced pick-point's bodies in NiceGUI's three.js scene, posed in the browser.
// The shapes come once per scene model and the poses once per pick-point (base64
// float32, shapes in each body's frame, poses in MuJoCo's Z-up world frame); a time
// moves every body and the force chart's marker here, with no message to the server.
import { THREE } from "nicegui-scene";

function decode(b64, Type) {
  const text = atob(b64);
  const bytes = new Uint8Array(text.length);
  for (let i = 0; i < text.length; i++) bytes[i] = text.charCodeAt(i);
  return new Type(bytes.buffer);
}

export default class PickReplay {
  create_mesh(shapes, track, t, chart_id) {
    this.root = new THREE.Group();
    this.root.name = "pick-replay";
    this.bodies = [];
    this.chart_id = chart_id;
    this.set_shapes(shapes);
    this.set_track(track, t);
    return this.root;
  }

  follow(chart_id) {
    this.chart_id = chart_id;
  }

  set_shapes(shapes) {
    for (const body of this.bodies) {
      body.removeFromParent();
      body.traverse((child) => {
        child.geometry?.dispose();
        child.material?.dispose();
      });
    }
    this.bodies = [];
    this.track = null;
    for (const body of shapes?.bodies || []) {
      const group = new THREE.Group();
      group.name = body.name;
      for (const geom of body.geoms) {
        const geometry = new THREE.BufferGeometry();
        geometry.setAttribute("position", new THREE.BufferAttribute(decode(geom.vertices, Float32Array), 3));
        geometry.setIndex(new THREE.BufferAttribute(decode(geom.faces, Uint32Array), 1));
        const material = new THREE.MeshPhongMaterial({
          color: geom.color,
          opacity: geom.opacity,
          transparent: geom.opacity < 1,
          side: THREE.DoubleSide,
          flatShading: true,
          // behind the table's grid lines, which lie in the table's top face
          polygonOffset: true,
          polygonOffsetFactor: 1,
          polygonOffsetUnits: 1,
        });
        const mesh = new THREE.Mesh(geometry, material);
        mesh.name = geom.name;
        mesh.userData.color = geom.color;
        group.add(mesh);
      }
      this.root.add(group);
      this.bodies.push(group);
    }
  }

  set_track(track, t) {
    if (!track || track.bodies.length !== this.bodies.length) {
      this.track = null;
      return;
    }
    this.track = {
      t: decode(track.t, Float32Array),
      position: decode(track.position, Float32Array),
      quat: decode(track.quat_wxyz, Float32Array),
    };
    // a body drawn in another colour for this pick-point (the object of a failed pick)
    for (const body of this.bodies) {
      const colour = track.colours?.[body.name];
      body.traverse((child) => child.material?.color.set(colour || child.userData.color));
    }
    this.show_time(t ?? this.track.t[0]);
  }

  row_at(t) {
    // the row whose time is nearest t (the times ascend)
    const times = this.track.t;
    let lo = 0;
    let hi = times.length - 1;
    while (lo < hi) {
      const mid = (lo + hi) >> 1;
      if (times[mid] < t) lo = mid + 1;
      else hi = mid;
    }
    return lo > 0 && t - times[lo - 1] < times[lo] - t ? lo - 1 : lo;
  }

  show_time(t) {
    if (!this.track) return;
    const k = this.row_at(Number(t));
    const n = this.bodies.length;
    const { position, quat } = this.track;
    this.bodies.forEach((body, b) => {
      const i = k * n + b;
      body.position.set(position[3 * i], position[3 * i + 1], position[3 * i + 2]);
      body.quaternion.set(quat[4 * i + 1], quat[4 * i + 2], quat[4 * i + 3], quat[4 * i]);
    });
    this.row = k;
    const chart = this.chart_id === null ? undefined : getElement(this.chart_id)?.chart;
    chart?.setOption({ series: [{ markLine: { data: [{ xAxis: this.track.t[k] }] } }] });
    return k;
  }
}
