// The frame-time chart of the viewer: the estimated frame time of the
// camera's CPV along the last frames, without impostors (grey) and with
// them (blue), against the target (red line).

const HISTORY = 240;

export class FrameChart {
  constructor(canvas) {
    this.canvas = canvas;
    this.ctx = canvas.getContext("2d");
    this.samples = [];
  }

  /// One frame: `original` and `final` in ms (null: no CPV), `target` ms.
  push(original, final, target) {
    this.samples.push({ original, final });
    if (this.samples.length > HISTORY) this.samples.shift();
    this.draw(target);
  }

  draw(target) {
    const { ctx, canvas } = this;
    const w = canvas.width, h = canvas.height, pad = 28;
    ctx.clearRect(0, 0, w, h);
    let top = target * 1.25;
    for (const s of this.samples) if (s.original !== null) top = Math.max(top, s.original * 1.05);
    const y = (ms) => h - pad - ((h - 2 * pad) * ms) / top;
    const x = (i) => pad + ((w - 2 * pad) * i) / (HISTORY - 1);
    ctx.font = "11px sans-serif";
    ctx.fillStyle = "#444";
    ctx.fillText(`${top.toFixed(1)} ms`, 2, pad - 6);
    ctx.fillText("0", 2, h - pad);
    ctx.strokeStyle = "#ccc";
    ctx.strokeRect(pad, pad, w - 2 * pad, h - 2 * pad);
    const line = (key, color) => {
      ctx.strokeStyle = color;
      ctx.lineWidth = 2;
      ctx.beginPath();
      let on = false;
      this.samples.forEach((s, i) => {
        if (s[key] === null) { on = false; return; }
        if (on) ctx.lineTo(x(i), y(s[key]));
        else ctx.moveTo(x(i), y(s[key]));
        on = true;
      });
      ctx.stroke();
    };
    line("original", "#9e9e9e");
    line("final", "#1e88e5");
    ctx.strokeStyle = "#e53935";
    ctx.lineWidth = 1;
    ctx.setLineDash([4, 3]);
    ctx.beginPath();
    ctx.moveTo(pad, y(target));
    ctx.lineTo(w - pad, y(target));
    ctx.stroke();
    ctx.setLineDash([]);
    ctx.fillStyle = "#e53935";
    ctx.fillText(`target ${target} ms`, w - pad - 80, y(target) - 4);
  }
}
