// scarp report viewer: one three.js scene per mapped target, built from the JSON block
// `scarp-view-data` (written by src/mission/report_viewer.rs). Coordinates are the target's map
// frame, ENU metres, z up. Orbit by dragging, zoom with the wheel, reset with a double click.
// `window.scarpViewerStats()` renders every view and returns pixel statistics (the headless
// browser test in .ci/run reads them).
(function () {
  'use strict';
  var dataNode = document.getElementById('scarp-view-data');
  if (!dataNode || typeof THREE === 'undefined') {
    return;
  }
  var targets = JSON.parse(dataNode.textContent);
  var BACKGROUND = 0xf7f7f7;

  function decode(b64, Type) {
    var bin = atob(b64);
    var bytes = new Uint8Array(bin.length);
    for (var i = 0; i < bin.length; i++) {
      bytes[i] = bin.charCodeAt(i);
    }
    return new Type(bytes.buffer);
  }

  // Distance → colour: blue (0) → cyan → green → yellow → red (≥ max).
  function ramp(t) {
    var stops = [[0.17, 0.32, 0.75], [0.1, 0.7, 0.85], [0.2, 0.75, 0.3], [0.95, 0.85, 0.2], [0.85, 0.15, 0.1]];
    var x = Math.min(Math.max(t, 0), 1) * (stops.length - 1);
    var i = Math.min(Math.floor(x), stops.length - 2);
    var f = x - i;
    return [0, 1, 2].map(function (k) { return stops[i][k] * (1 - f) + stops[i + 1][k] * f; });
  }

  function meshGeometry(positions, indices) {
    var g = new THREE.BufferGeometry();
    g.setAttribute('position', new THREE.BufferAttribute(positions, 3));
    g.setIndex(new THREE.BufferAttribute(indices, 1));
    g.computeVertexNormals();
    g.computeBoundingSphere();
    return g;
  }

  function makeViewer(t) {
    var canvas = document.getElementById('view-' + t.id);
    if (!canvas) {
      return null;
    }
    var renderer;
    try {
      renderer = new THREE.WebGLRenderer({ canvas: canvas, antialias: true, preserveDrawingBuffer: true });
    } catch (e) {
      var note = document.createElement('p');
      note.textContent = 'This browser cannot show the 3D view (WebGL unavailable): ' + e;
      canvas.replaceWith(note);
      return null;
    }
    renderer.setPixelRatio(1);
    renderer.setSize(canvas.width, canvas.height, false);
    var scene = new THREE.Scene();
    scene.background = new THREE.Color(BACKGROUND);

    // The reconstruction, with camera colours or distance-to-truth colours.
    var positions = decode(t.positions, Float32Array);
    var geometry = meshGeometry(positions, decode(t.indices, Uint32Array));
    var n = positions.length / 3;
    var cameraColours = t.colors
      ? new THREE.BufferAttribute(decode(t.colors, Uint8Array), 3, true)
      : new THREE.BufferAttribute(new Float32Array(n * 3).fill(0.7), 3);
    geometry.setAttribute('color', cameraColours);
    var errorColours = null;
    var errorMax = 0.02;
    if (t.error_m) {
      var err = decode(t.error_m, Float32Array);
      errorMax = Math.max(0.005, (t.error_p90_m || 0.01) * 1.5);
      var c = new Float32Array(n * 3);
      for (var i = 0; i < n; i++) {
        var rgb = ramp(err[i] / errorMax);
        c[3 * i] = rgb[0];
        c[3 * i + 1] = rgb[1];
        c[3 * i + 2] = rgb[2];
      }
      errorColours = new THREE.BufferAttribute(c, 3);
    }
    var material = new THREE.MeshStandardMaterial({
      vertexColors: true, side: THREE.DoubleSide, roughness: 0.9, metalness: 0.0
    });
    var rock = new THREE.Mesh(geometry, material);
    scene.add(rock);

    var sphere = geometry.boundingSphere;
    var size = Math.max(sphere.radius, 0.05);
    var layers = {};

    if (t.gt_positions && t.gt_indices) {
      var gtGeometry = meshGeometry(decode(t.gt_positions, Float32Array), decode(t.gt_indices, Uint32Array));
      var gt = new THREE.Mesh(gtGeometry, new THREE.MeshStandardMaterial({
        color: 0x1a9641, transparent: true, opacity: 0.45, side: THREE.DoubleSide, depthWrite: false,
        // Drawn a little towards the camera, so it shows where it coincides with the rock.
        polygonOffset: true, polygonOffsetFactor: -2, polygonOffsetUnits: -8
      }));
      gt.visible = false;
      scene.add(gt);
      layers.gt = gt;
    }
    // The contact polygon and the centre of mass are drawn through the rock (no depth test):
    // the contact lies under it.
    if (t.contact_polygon && t.contact_polygon.length >= 2) {
      var pts = t.contact_polygon.map(function (p) { return new THREE.Vector3(p[0], p[1], p[2]); });
      var contact = new THREE.LineLoop(
        new THREE.BufferGeometry().setFromPoints(pts),
        new THREE.LineBasicMaterial({ color: 0xd62728, depthTest: false })
      );
      contact.renderOrder = 10;
      scene.add(contact);
      layers.contact = contact;
    }
    if (t.center_of_mass) {
      var com = new THREE.Group();
      var p = t.center_of_mass;
      var ball = new THREE.Mesh(
        new THREE.SphereGeometry(size * 0.04, 16, 12),
        new THREE.MeshBasicMaterial({ color: 0xff7f0e, depthTest: false })
      );
      ball.position.set(p[0], p[1], p[2]);
      ball.renderOrder = 11;
      com.add(ball);
      if (t.contact_polygon && t.contact_polygon.length) {
        var zc = t.contact_polygon.reduce(function (s, q) { return s + q[2]; }, 0) / t.contact_polygon.length;
        var plumb = new THREE.Line(
          new THREE.BufferGeometry().setFromPoints([new THREE.Vector3(p[0], p[1], p[2]), new THREE.Vector3(p[0], p[1], zc)]),
          new THREE.LineBasicMaterial({ color: 0xff7f0e, depthTest: false })
        );
        plumb.renderOrder = 11;
        com.add(plumb);
      }
      scene.add(com);
      layers.com = com;
    }

    var camera = new THREE.PerspectiveCamera(40, canvas.width / canvas.height, size * 0.01, size * 100);
    camera.up.set(0, 0, 1);
    scene.add(camera);
    scene.add(new THREE.HemisphereLight(0xffffff, 0x777777, 1.6));
    var headlight = new THREE.DirectionalLight(0xffffff, 1.4);
    headlight.position.set(0.3, 0.6, 0.2);
    camera.add(headlight);

    var home = { radius: size * 3.0, theta: -Math.PI / 2 + 0.6, phi: 1.15 };
    var orbit = { radius: home.radius, theta: home.theta, phi: home.phi };
    var center = sphere.center.clone();

    function draw() {
      var r = orbit.radius;
      camera.position.set(
        center.x + r * Math.sin(orbit.phi) * Math.cos(orbit.theta),
        center.y + r * Math.sin(orbit.phi) * Math.sin(orbit.theta),
        center.z + r * Math.cos(orbit.phi)
      );
      camera.lookAt(center);
      renderer.render(scene, camera);
    }

    var drag = null;
    canvas.addEventListener('pointerdown', function (e) {
      drag = { x: e.clientX, y: e.clientY };
      canvas.setPointerCapture(e.pointerId);
    });
    canvas.addEventListener('pointermove', function (e) {
      if (!drag) {
        return;
      }
      orbit.theta -= (e.clientX - drag.x) * 0.01;
      orbit.phi = Math.min(Math.max(orbit.phi - (e.clientY - drag.y) * 0.01, 0.02), Math.PI - 0.02);
      drag = { x: e.clientX, y: e.clientY };
      draw();
    });
    canvas.addEventListener('pointerup', function () { drag = null; });
    canvas.addEventListener('wheel', function (e) {
      e.preventDefault();
      orbit.radius = Math.min(Math.max(orbit.radius * Math.exp(e.deltaY * 0.001), size * 0.2), size * 30);
      draw();
    }, { passive: false });
    canvas.addEventListener('dblclick', function () {
      orbit.radius = home.radius;
      orbit.theta = home.theta;
      orbit.phi = home.phi;
      draw();
    });

    var legend = document.getElementById('legend-' + t.id);
    function setColours(which) {
      var useError = which === 'error' && errorColours;
      geometry.setAttribute('color', useError ? errorColours : cameraColours);
      if (legend) {
        legend.innerHTML = useError
          ? '<span style="display:inline-block;width:160px;height:10px;vertical-align:middle;background:linear-gradient(to right,' +
            [0, 0.25, 0.5, 0.75, 1].map(function (s) {
              var c = ramp(s);
              return 'rgb(' + c.map(function (v) { return Math.round(v * 255); }).join(',') + ')';
            }).join(',') + ')"></span> 0 – ' + (errorMax * 1000).toFixed(1) + ' mm (and beyond)'
          : '';
      }
      draw();
    }

    return {
      draw: draw,
      renderer: renderer,
      setLayer: function (name, on) {
        if (layers[name]) {
          layers[name].visible = on;
          draw();
        }
      },
      setColours: setColours,
      layers: layers
    };
  }

  var viewers = {};
  targets.forEach(function (t) {
    var v = makeViewer(t);
    if (v) {
      viewers[t.id] = v;
      v.draw();
    }
  });

  document.querySelectorAll('input[data-target]').forEach(function (input) {
    input.addEventListener('change', function () {
      var v = viewers[input.dataset.target];
      if (!v) {
        return;
      }
      if (input.dataset.layer) {
        v.setLayer(input.dataset.layer, input.checked);
      } else if (input.dataset.colour && input.checked) {
        v.setColours(input.dataset.colour);
      }
    });
  });

  window.scarpViewers = viewers;
  // Pixel statistics of each view, rendered now: the fraction of pixels that differ from the
  // background, the number of distinct colours (to 4 bits a channel), and the mean and standard
  // deviation of the luminance.
  window.scarpViewerStats = function () {
    var out = {};
    Object.keys(viewers).forEach(function (id) {
      var v = viewers[id];
      v.draw();
      var gl = v.renderer.getContext();
      var w = gl.drawingBufferWidth;
      var h = gl.drawingBufferHeight;
      var px = new Uint8Array(w * h * 4);
      gl.readPixels(0, 0, w, h, gl.RGBA, gl.UNSIGNED_BYTE, px);
      var bg = [0xf7, 0xf7, 0xf7];
      var differ = 0;
      var sum = 0;
      var sum2 = 0;
      var colours = new Set();
      for (var i = 0; i < w * h; i++) {
        var r = px[4 * i];
        var g = px[4 * i + 1];
        var b = px[4 * i + 2];
        if (Math.abs(r - bg[0]) + Math.abs(g - bg[1]) + Math.abs(b - bg[2]) > 24) {
          differ++;
        }
        var y = 0.2126 * r + 0.7152 * g + 0.0722 * b;
        sum += y;
        sum2 += y * y;
        colours.add(((r >> 4) << 8) | ((g >> 4) << 4) | (b >> 4));
      }
      var mean = sum / (w * h);
      out[id] = {
        width: w,
        height: h,
        nonBackgroundFraction: differ / (w * h),
        distinctColours: colours.size,
        meanLuma: mean,
        stdLuma: Math.sqrt(Math.max(sum2 / (w * h) - mean * mean, 0))
      };
    });
    return out;
  };
})();
